"""Hold your own calibration method to a baseline you recorded (``photoquant.testing``).

Record the baseline once, with the method you trust (here the built-in
``"Robertson 2003"`` stands for yours; a plug-in's name works the same way
once its distribution is installed), on the experiment and camera that
matter to it::

    photoquant validate --experiments response --preset ccd \\
        --method response="Robertson 2003" --write-baseline my_method.baseline.json

That runs the configuration over 8 master seeds and stores each metric's
value, spread and tolerance (5 seed-to-seed spreads), the configuration and
the versions. Commit the file beside this test; ``pytest`` then fails,
listing every metric that moved the wrong way beyond its tolerance, when a
later version of the method (or of photoquant) makes it worse. A baseline
of another configuration is refused with one line before anything runs.
Run it with ``python -m pytest examples/test_my_method_baseline.py``.
"""

from pathlib import Path

from photoquant.testing import check_against_baseline


def test_my_method_holds_its_baseline():
    check_against_baseline(
        Path(__file__).with_name("my_method.baseline.json"),
        methods={"response": "Robertson 2003"},
        experiments=["response"],
        presets=["ccd"],
    )
