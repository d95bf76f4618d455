"""Two trackers on one vehicle (:mod:`localizer.tracking.crowd`): boxes worked by hand."""

from localizer.tracking.crowd import NEAR_FRAMES, STATUS, Crowd, same_spot


def test_same_spot_by_hand():
    # centres (20, 10) and (23, 14): 5 px apart; the smaller box's shorter side 20 px, a quarter of it 5 px
    assert same_spot((0, 0, 40, 20), (3, 4, 40, 20))
    assert not same_spot((0, 0, 40, 20), (3, 5, 40, 20))  # 5.8 px apart
    # a drawn box inside a tracker's: centres 0 px apart
    assert same_spot((100, 100, 40, 40), (105, 105, 30, 30))
    # side by side, 18 px apart: two vehicles
    assert not same_spot((100, 100, 40, 20), (118, 100, 40, 20))


def test_two_trackers_on_one_vehicle_both_get_no_fix_until_they_part():
    crowd = Crowd()
    assert crowd.vet("uuv1", 10, (100, 100, 40, 20)) is None
    assert crowd.vet("uuv2", 10, (300, 100, 40, 20)) is None  # apart
    # uuv2's tracker re-locked onto uuv1's vehicle
    assert crowd.vet("uuv2", 11, (104, 101, 36, 18)) == STATUS
    assert crowd.vet("uuv1", 11, (102, 100, 40, 20)) == STATUS  # ... and uuv1's is told too
    assert crowd.vet("uuv1", 12, (102, 100, 40, 20)) == STATUS
    assert crowd.vet("uuv2", 13, None) is None  # uuv2 released: uuv1 alone again
    assert crowd.vet("uuv1", 13, (103, 100, 40, 20)) is None


def test_boxes_frames_apart_are_not_compared():
    crowd = Crowd()
    crowd.vet("uuv1", 20, (100, 100, 40, 20))
    # uuv1's box is too old to compare
    assert crowd.vet("uuv2", 20 + NEAR_FRAMES + 1, (101, 100, 40, 20)) is None


def test_a_pipeline_running_behind_the_other_still_tells_both():
    """uuv1's pipeline is at frame 40 when uuv2's reaches frame 31, on uuv1's box of that frame: both are told, and
    uuv1 stays told while no frames near each other show them apart."""
    crowd = Crowd()
    for frame in range(30, 41):
        assert crowd.vet("uuv1", frame, (200 + frame, 50, 40, 20)) is None
    assert crowd.vet("uuv2", 31, (232, 51, 40, 20)) == STATUS
    assert crowd.vet("uuv1", 41, (241, 50, 40, 20)) == STATUS
    # parted at frame 40 (uuv1's box there: 240)
    assert crowd.vet("uuv2", 40, (300, 50, 40, 20)) is None
    assert crowd.vet("uuv1", 42, (242, 50, 40, 20)) is None
