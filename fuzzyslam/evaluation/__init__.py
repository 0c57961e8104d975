"""fuzzyslam.evaluation: errors of an estimate against ground truth, and the paper's figures.

Modules:
    align     Umeyama (1991) rigid / similarity alignment of point sets (as evo for APE).
    metrics   pure metric functions: association in time, pose errors, stats, APE, RPE per
              metre, NEES / NIS chi-square tests, one-to-one lamp matching, phases.
    core      ``evaluate(Truth, Estimate, EvalParams) -> Evaluation``: every metric, no I/O.
    figures   Fig. 1 (paths, lamps, FGM), Fig. 3 (errors vs time), Fig. 4 (per-lamp errors,
              several labelled sets side by side), NEES/NIS plot.
    report    metrics.json and report.md.
    evaluate  the edge: kind detection, file readers, ``run_evaluate`` (the CLI's stage).
"""
