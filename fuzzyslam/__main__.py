from fuzzyslam.cli import main

main()
