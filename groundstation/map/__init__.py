"""The site on a map: web-map tiles of a georeferenced image (the bottom's mosaic, an orthophoto) for the live
page's base map and for GIS (:mod:`.tiles`)."""
