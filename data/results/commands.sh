#!/bin/sh
# Every step of 'fuzzyslam reproduce', as stage commands; run from this directory.
# The same commands with the same seeds write the same files.
set -e
mkdir -p seed0
fuzzyslam simulate paper.yaml -o seed0/paper.mcap --seed 0
fuzzyslam simulate paper_bumps.yaml -o seed0/bumps.mcap --seed 0
fuzzyslam simulate paper_dark.yaml -o seed0/dark.mcap --seed 0
fuzzyslam simulate paper_people.yaml -o seed0/people.mcap --seed 0
fuzzyslam run seed0/paper.mcap -o seed0/AB --config paper.yaml
fuzzyslam map seed0/paper.mcap --trajectory seed0/AB/trajectory.tum --landmarks seed0/AB/landmarks.yaml -o seed0/fgm --config paper.yaml --calibration seed0/AB/calibration.csv
fuzzyslam run seed0/paper.mcap -o seed0/C --config paper.yaml --map seed0/fgm --fix heading
fuzzyslam run seed0/bumps.mcap -o seed0/D --config paper_bumps.yaml --map seed0/fgm --fix heading --fix-from 0
fuzzyslam run seed0/paper.mcap -o seed0/C_pose --config paper.yaml --map seed0/fgm --fix pose
fuzzyslam run seed0/dark.mcap -o seed0/dark_none --config paper_dark.yaml
fuzzyslam map seed0/dark.mcap --trajectory seed0/dark_none/trajectory.tum --landmarks seed0/dark_none/landmarks.yaml -o seed0/dark_fgm --config paper_dark.yaml --calibration seed0/dark_none/calibration.csv
fuzzyslam run seed0/people.mcap -o seed0/people_none --config paper_people.yaml
fuzzyslam map seed0/people.mcap --trajectory seed0/people_none/trajectory.tum --landmarks seed0/people_none/landmarks.yaml -o seed0/people_fgm --config paper_people.yaml --calibration seed0/people_none/calibration.csv
fuzzyslam run seed0/dark.mcap -o seed0/dark_heading --config paper_dark.yaml --map seed0/dark_fgm --fix heading
fuzzyslam run seed0/dark.mcap -o seed0/dark_pose --config paper_dark.yaml --map seed0/dark_fgm --fix pose
fuzzyslam run seed0/people.mcap -o seed0/people_pose --config paper_people.yaml --map seed0/people_fgm --fix pose
fuzzyslam evaluate seed0/paper.mcap seed0/AB -o seed0/eval_AB --map seed0/fgm --label 'A+B: lamps only'
fuzzyslam evaluate seed0/paper.mcap seed0/C -o seed0/eval_C --map seed0/fgm --label 'C: heading fixes (paper)' --compare 'A+B: lamps only=seed0/AB'
fuzzyslam evaluate seed0/paper.mcap seed0/C_pose -o seed0/eval_C_pose --map seed0/fgm --label 'C: pose fixes (beyond)'
fuzzyslam evaluate seed0/bumps.mcap seed0/D -o seed0/eval_D --map seed0/fgm --label 'D: bumps, heading fixes'
fuzzyslam evaluate seed0/dark.mcap seed0/dark_none -o seed0/eval_dark_none --map seed0/dark_fgm --label 'all lamps off: no fixes'
fuzzyslam evaluate seed0/dark.mcap seed0/dark_heading -o seed0/eval_dark_heading --map seed0/dark_fgm --label 'all lamps off: heading fixes'
fuzzyslam evaluate seed0/dark.mcap seed0/dark_pose -o seed0/eval_dark_pose --map seed0/dark_fgm --label 'all lamps off: pose fixes' --compare 'all lamps off: heading fixes=seed0/dark_heading' --compare 'all lamps off: no fixes=seed0/dark_none'
fuzzyslam evaluate seed0/people.mcap seed0/people_pose -o seed0/eval_people_pose --map seed0/people_fgm --label 'people and boxes: pose fixes'
mkdir -p seed1
fuzzyslam simulate paper.yaml -o seed1/paper.mcap --seed 1
fuzzyslam simulate paper_bumps.yaml -o seed1/bumps.mcap --seed 1
fuzzyslam simulate paper_dark.yaml -o seed1/dark.mcap --seed 1
fuzzyslam simulate paper_people.yaml -o seed1/people.mcap --seed 1
fuzzyslam run seed1/paper.mcap -o seed1/AB --config paper.yaml
fuzzyslam map seed1/paper.mcap --trajectory seed1/AB/trajectory.tum --landmarks seed1/AB/landmarks.yaml -o seed1/fgm --config paper.yaml --calibration seed1/AB/calibration.csv
fuzzyslam run seed1/paper.mcap -o seed1/C --config paper.yaml --map seed1/fgm --fix heading
fuzzyslam run seed1/bumps.mcap -o seed1/D --config paper_bumps.yaml --map seed1/fgm --fix heading --fix-from 0
fuzzyslam run seed1/paper.mcap -o seed1/C_pose --config paper.yaml --map seed1/fgm --fix pose
fuzzyslam run seed1/dark.mcap -o seed1/dark_none --config paper_dark.yaml
fuzzyslam map seed1/dark.mcap --trajectory seed1/dark_none/trajectory.tum --landmarks seed1/dark_none/landmarks.yaml -o seed1/dark_fgm --config paper_dark.yaml --calibration seed1/dark_none/calibration.csv
fuzzyslam run seed1/people.mcap -o seed1/people_none --config paper_people.yaml
fuzzyslam map seed1/people.mcap --trajectory seed1/people_none/trajectory.tum --landmarks seed1/people_none/landmarks.yaml -o seed1/people_fgm --config paper_people.yaml --calibration seed1/people_none/calibration.csv
fuzzyslam run seed1/dark.mcap -o seed1/dark_heading --config paper_dark.yaml --map seed1/dark_fgm --fix heading
fuzzyslam run seed1/dark.mcap -o seed1/dark_pose --config paper_dark.yaml --map seed1/dark_fgm --fix pose
fuzzyslam run seed1/people.mcap -o seed1/people_pose --config paper_people.yaml --map seed1/people_fgm --fix pose
fuzzyslam evaluate seed1/paper.mcap seed1/AB -o seed1/eval_AB --map seed1/fgm --label 'A+B: lamps only'
fuzzyslam evaluate seed1/paper.mcap seed1/C -o seed1/eval_C --map seed1/fgm --label 'C: heading fixes (paper)' --compare 'A+B: lamps only=seed1/AB'
fuzzyslam evaluate seed1/paper.mcap seed1/C_pose -o seed1/eval_C_pose --map seed1/fgm --label 'C: pose fixes (beyond)'
fuzzyslam evaluate seed1/bumps.mcap seed1/D -o seed1/eval_D --map seed1/fgm --label 'D: bumps, heading fixes'
fuzzyslam evaluate seed1/dark.mcap seed1/dark_none -o seed1/eval_dark_none --map seed1/dark_fgm --label 'all lamps off: no fixes'
fuzzyslam evaluate seed1/dark.mcap seed1/dark_heading -o seed1/eval_dark_heading --map seed1/dark_fgm --label 'all lamps off: heading fixes'
fuzzyslam evaluate seed1/dark.mcap seed1/dark_pose -o seed1/eval_dark_pose --map seed1/dark_fgm --label 'all lamps off: pose fixes' --compare 'all lamps off: heading fixes=seed1/dark_heading' --compare 'all lamps off: no fixes=seed1/dark_none'
fuzzyslam evaluate seed1/people.mcap seed1/people_pose -o seed1/eval_people_pose --map seed1/people_fgm --label 'people and boxes: pose fixes'
mkdir -p seed2
fuzzyslam simulate paper.yaml -o seed2/paper.mcap --seed 2
fuzzyslam simulate paper_bumps.yaml -o seed2/bumps.mcap --seed 2
fuzzyslam simulate paper_dark.yaml -o seed2/dark.mcap --seed 2
fuzzyslam simulate paper_people.yaml -o seed2/people.mcap --seed 2
fuzzyslam run seed2/paper.mcap -o seed2/AB --config paper.yaml
fuzzyslam map seed2/paper.mcap --trajectory seed2/AB/trajectory.tum --landmarks seed2/AB/landmarks.yaml -o seed2/fgm --config paper.yaml --calibration seed2/AB/calibration.csv
fuzzyslam run seed2/paper.mcap -o seed2/C --config paper.yaml --map seed2/fgm --fix heading
fuzzyslam run seed2/bumps.mcap -o seed2/D --config paper_bumps.yaml --map seed2/fgm --fix heading --fix-from 0
fuzzyslam run seed2/paper.mcap -o seed2/C_pose --config paper.yaml --map seed2/fgm --fix pose
fuzzyslam run seed2/dark.mcap -o seed2/dark_none --config paper_dark.yaml
fuzzyslam map seed2/dark.mcap --trajectory seed2/dark_none/trajectory.tum --landmarks seed2/dark_none/landmarks.yaml -o seed2/dark_fgm --config paper_dark.yaml --calibration seed2/dark_none/calibration.csv
fuzzyslam run seed2/people.mcap -o seed2/people_none --config paper_people.yaml
fuzzyslam map seed2/people.mcap --trajectory seed2/people_none/trajectory.tum --landmarks seed2/people_none/landmarks.yaml -o seed2/people_fgm --config paper_people.yaml --calibration seed2/people_none/calibration.csv
fuzzyslam run seed2/dark.mcap -o seed2/dark_heading --config paper_dark.yaml --map seed2/dark_fgm --fix heading
fuzzyslam run seed2/dark.mcap -o seed2/dark_pose --config paper_dark.yaml --map seed2/dark_fgm --fix pose
fuzzyslam run seed2/people.mcap -o seed2/people_pose --config paper_people.yaml --map seed2/people_fgm --fix pose
fuzzyslam evaluate seed2/paper.mcap seed2/AB -o seed2/eval_AB --map seed2/fgm --label 'A+B: lamps only'
fuzzyslam evaluate seed2/paper.mcap seed2/C -o seed2/eval_C --map seed2/fgm --label 'C: heading fixes (paper)' --compare 'A+B: lamps only=seed2/AB'
fuzzyslam evaluate seed2/paper.mcap seed2/C_pose -o seed2/eval_C_pose --map seed2/fgm --label 'C: pose fixes (beyond)'
fuzzyslam evaluate seed2/bumps.mcap seed2/D -o seed2/eval_D --map seed2/fgm --label 'D: bumps, heading fixes'
fuzzyslam evaluate seed2/dark.mcap seed2/dark_none -o seed2/eval_dark_none --map seed2/dark_fgm --label 'all lamps off: no fixes'
fuzzyslam evaluate seed2/dark.mcap seed2/dark_heading -o seed2/eval_dark_heading --map seed2/dark_fgm --label 'all lamps off: heading fixes'
fuzzyslam evaluate seed2/dark.mcap seed2/dark_pose -o seed2/eval_dark_pose --map seed2/dark_fgm --label 'all lamps off: pose fixes' --compare 'all lamps off: heading fixes=seed2/dark_heading' --compare 'all lamps off: no fixes=seed2/dark_none'
fuzzyslam evaluate seed2/people.mcap seed2/people_pose -o seed2/eval_people_pose --map seed2/people_fgm --label 'people and boxes: pose fixes'
mkdir -p seed3
fuzzyslam simulate paper.yaml -o seed3/paper.mcap --seed 3
fuzzyslam simulate paper_bumps.yaml -o seed3/bumps.mcap --seed 3
fuzzyslam simulate paper_dark.yaml -o seed3/dark.mcap --seed 3
fuzzyslam simulate paper_people.yaml -o seed3/people.mcap --seed 3
fuzzyslam run seed3/paper.mcap -o seed3/AB --config paper.yaml
fuzzyslam map seed3/paper.mcap --trajectory seed3/AB/trajectory.tum --landmarks seed3/AB/landmarks.yaml -o seed3/fgm --config paper.yaml --calibration seed3/AB/calibration.csv
fuzzyslam run seed3/paper.mcap -o seed3/C --config paper.yaml --map seed3/fgm --fix heading
fuzzyslam run seed3/bumps.mcap -o seed3/D --config paper_bumps.yaml --map seed3/fgm --fix heading --fix-from 0
fuzzyslam run seed3/paper.mcap -o seed3/C_pose --config paper.yaml --map seed3/fgm --fix pose
fuzzyslam run seed3/dark.mcap -o seed3/dark_none --config paper_dark.yaml
fuzzyslam map seed3/dark.mcap --trajectory seed3/dark_none/trajectory.tum --landmarks seed3/dark_none/landmarks.yaml -o seed3/dark_fgm --config paper_dark.yaml --calibration seed3/dark_none/calibration.csv
fuzzyslam run seed3/people.mcap -o seed3/people_none --config paper_people.yaml
fuzzyslam map seed3/people.mcap --trajectory seed3/people_none/trajectory.tum --landmarks seed3/people_none/landmarks.yaml -o seed3/people_fgm --config paper_people.yaml --calibration seed3/people_none/calibration.csv
fuzzyslam run seed3/dark.mcap -o seed3/dark_heading --config paper_dark.yaml --map seed3/dark_fgm --fix heading
fuzzyslam run seed3/dark.mcap -o seed3/dark_pose --config paper_dark.yaml --map seed3/dark_fgm --fix pose
fuzzyslam run seed3/people.mcap -o seed3/people_pose --config paper_people.yaml --map seed3/people_fgm --fix pose
fuzzyslam evaluate seed3/paper.mcap seed3/AB -o seed3/eval_AB --map seed3/fgm --label 'A+B: lamps only'
fuzzyslam evaluate seed3/paper.mcap seed3/C -o seed3/eval_C --map seed3/fgm --label 'C: heading fixes (paper)' --compare 'A+B: lamps only=seed3/AB'
fuzzyslam evaluate seed3/paper.mcap seed3/C_pose -o seed3/eval_C_pose --map seed3/fgm --label 'C: pose fixes (beyond)'
fuzzyslam evaluate seed3/bumps.mcap seed3/D -o seed3/eval_D --map seed3/fgm --label 'D: bumps, heading fixes'
fuzzyslam evaluate seed3/dark.mcap seed3/dark_none -o seed3/eval_dark_none --map seed3/dark_fgm --label 'all lamps off: no fixes'
fuzzyslam evaluate seed3/dark.mcap seed3/dark_heading -o seed3/eval_dark_heading --map seed3/dark_fgm --label 'all lamps off: heading fixes'
fuzzyslam evaluate seed3/dark.mcap seed3/dark_pose -o seed3/eval_dark_pose --map seed3/dark_fgm --label 'all lamps off: pose fixes' --compare 'all lamps off: heading fixes=seed3/dark_heading' --compare 'all lamps off: no fixes=seed3/dark_none'
fuzzyslam evaluate seed3/people.mcap seed3/people_pose -o seed3/eval_people_pose --map seed3/people_fgm --label 'people and boxes: pose fixes'
mkdir -p seed4
fuzzyslam simulate paper.yaml -o seed4/paper.mcap --seed 4
fuzzyslam simulate paper_bumps.yaml -o seed4/bumps.mcap --seed 4
fuzzyslam simulate paper_dark.yaml -o seed4/dark.mcap --seed 4
fuzzyslam simulate paper_people.yaml -o seed4/people.mcap --seed 4
fuzzyslam run seed4/paper.mcap -o seed4/AB --config paper.yaml
fuzzyslam map seed4/paper.mcap --trajectory seed4/AB/trajectory.tum --landmarks seed4/AB/landmarks.yaml -o seed4/fgm --config paper.yaml --calibration seed4/AB/calibration.csv
fuzzyslam run seed4/paper.mcap -o seed4/C --config paper.yaml --map seed4/fgm --fix heading
fuzzyslam run seed4/bumps.mcap -o seed4/D --config paper_bumps.yaml --map seed4/fgm --fix heading --fix-from 0
fuzzyslam run seed4/paper.mcap -o seed4/C_pose --config paper.yaml --map seed4/fgm --fix pose
fuzzyslam run seed4/dark.mcap -o seed4/dark_none --config paper_dark.yaml
fuzzyslam map seed4/dark.mcap --trajectory seed4/dark_none/trajectory.tum --landmarks seed4/dark_none/landmarks.yaml -o seed4/dark_fgm --config paper_dark.yaml --calibration seed4/dark_none/calibration.csv
fuzzyslam run seed4/people.mcap -o seed4/people_none --config paper_people.yaml
fuzzyslam map seed4/people.mcap --trajectory seed4/people_none/trajectory.tum --landmarks seed4/people_none/landmarks.yaml -o seed4/people_fgm --config paper_people.yaml --calibration seed4/people_none/calibration.csv
fuzzyslam run seed4/dark.mcap -o seed4/dark_heading --config paper_dark.yaml --map seed4/dark_fgm --fix heading
fuzzyslam run seed4/dark.mcap -o seed4/dark_pose --config paper_dark.yaml --map seed4/dark_fgm --fix pose
fuzzyslam run seed4/people.mcap -o seed4/people_pose --config paper_people.yaml --map seed4/people_fgm --fix pose
fuzzyslam evaluate seed4/paper.mcap seed4/AB -o seed4/eval_AB --map seed4/fgm --label 'A+B: lamps only'
fuzzyslam evaluate seed4/paper.mcap seed4/C -o seed4/eval_C --map seed4/fgm --label 'C: heading fixes (paper)' --compare 'A+B: lamps only=seed4/AB'
fuzzyslam evaluate seed4/paper.mcap seed4/C_pose -o seed4/eval_C_pose --map seed4/fgm --label 'C: pose fixes (beyond)'
fuzzyslam evaluate seed4/bumps.mcap seed4/D -o seed4/eval_D --map seed4/fgm --label 'D: bumps, heading fixes'
fuzzyslam evaluate seed4/dark.mcap seed4/dark_none -o seed4/eval_dark_none --map seed4/dark_fgm --label 'all lamps off: no fixes'
fuzzyslam evaluate seed4/dark.mcap seed4/dark_heading -o seed4/eval_dark_heading --map seed4/dark_fgm --label 'all lamps off: heading fixes'
fuzzyslam evaluate seed4/dark.mcap seed4/dark_pose -o seed4/eval_dark_pose --map seed4/dark_fgm --label 'all lamps off: pose fixes' --compare 'all lamps off: heading fixes=seed4/dark_heading' --compare 'all lamps off: no fixes=seed4/dark_none'
fuzzyslam evaluate seed4/people.mcap seed4/people_pose -o seed4/eval_people_pose --map seed4/people_fgm --label 'people and boxes: pose fixes'
