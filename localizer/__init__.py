"""skyfix's pure computation: camera model, attitude, refraction, time alignment, geodesy, fixes.

No I/O and no asyncio here; every function works on scalars or numpy arrays.
"""
