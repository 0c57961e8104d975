"""``fuzzyslam reproduce``: the paper's experiment (docs/experiment.md) from one command.

plan (the steps, pure) -> execute (worker processes) -> table (aggregation over seeds,
pure) -> report (report.md, results.json, commands.sh, summary.png); stage ties them.
"""
