"""fuzzyslam.slam"""
