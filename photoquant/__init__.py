"""photoquant: radiometric camera calibration and photoquantity measurement.

Calibrate a camera once (response per channel, colour balance, sensor
non-uniformity, vignetting) and then measure the photoquantity of any static
scene from a few exposures, following the reference paper
(``shared/reference/paper.txt``).
"""

__version__ = "0.1.0"
