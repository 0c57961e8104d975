"""fuzzyslam.fixes"""
