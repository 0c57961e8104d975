"""fuzzyslam: EKF-SLAM on ceiling lamps with fuzzy sonar maps and Hough heading fixes."""

__version__ = "0.1.0"
