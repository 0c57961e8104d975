"""fuzzyslam.sim"""
