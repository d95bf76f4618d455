"""The operator's web page, served by ``skyfix run`` (``--ui``, default ``127.0.0.1:8080``; ``--no-ui``).

- :mod:`.bind`: the ``--ui`` address and token rules;
- :mod:`.feed`: the frames the pipeline tracked, as JPEG with their fix's overlay, only while a page watches;
- :mod:`.topview`: the map's geometry: the UAV, the camera's footprint on the water, each UUV's track;
- :mod:`.palette`: each UUV's colour (several UUVs, ``[[uuv]]``: every one is shown, in its colour);
- :mod:`.server`: the aiohttp application and its worker (page, WebSocket, commands);
- ``static/``: the page itself (HTML, CSS, JavaScript; nothing from the internet).
"""
