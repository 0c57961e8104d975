"""fuzzyslam.maps"""
