"""Dependencies as the project card names them: OpenCV comes from ``opencv-contrib-python-headless``,
and it is the only OpenCV wheel in the environment (the wheels share one ``cv2`` folder, so a
second one silently replaces the first one's files)."""

from importlib import metadata

OPENCV_WHEELS = ("opencv-python", "opencv-python-headless", "opencv-contrib-python", "opencv-contrib-python-headless")


def _installed(name: str) -> bool:
    try:
        metadata.distribution(name)
    except metadata.PackageNotFoundError:
        return False
    return True


def test_only_the_contrib_headless_opencv_wheel_is_installed():
    present = [w for w in OPENCV_WHEELS if _installed(w)]
    assert present == ["opencv-contrib-python-headless"], (
        f"OpenCV wheels installed: {present}; run `make venv` (it clears the others) or "
        "`pip uninstall` them and reinstall opencv-contrib-python-headless")


def test_cv2_has_the_contrib_modules():
    import cv2

    assert hasattr(cv2, "ximgproc") and hasattr(cv2, "aruco")
