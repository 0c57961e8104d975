"""`fuzzyslam simulate`: the paper's robot, world and sensors, written to one MCAP file."""

from __future__ import annotations

import click

from fuzzyslam.cli import cli, emit, seed_option


@cli.command("simulate")
@click.argument("config", required=False, default=None)
@click.option(
    "-o", "--output", "output", required=True, type=click.Path(readable=False),
    help="The MCAP recording to write (e.g. sensors.mcap); written atomically.",
)  # fmt: skip
@seed_option
@click.option(
    "--preview", type=click.Path(readable=False), default=None,
    help="Also write a PNG of walls, lamps (lit/failed), true and dead-reckoning paths.",
)  # fmt: skip
@click.option(
    "--truth-tum", type=click.Path(readable=False), default=None,
    help="Also write the ground truth (/ground_truth/odom) as a TUM trajectory (for evo).",
)  # fmt: skip
def simulate(
    config: str | None, output: str, seed: int | None, preview: str | None, truth_tum: str | None
) -> None:
    """Simulate the robot, world and sensors of CONFIG and write one MCAP recording.

    CONFIG is a YAML path or an embedded config name (default: paper.yaml, the
    paper's six runs with 7 of 15 lamps failing from run 5; quick.yaml: two runs;
    sample.yaml: one lap with a bump; paper_bumps.yaml: a 10-degree bump in each
    run; paper_dark.yaml: every lamp off from run 5). Its sections world, robot,
    sonar, camera and scenario drive the simulation; unknown keys are errors.

    The robot drives the scenario's runs around the corridor loop (odd runs
    forward, even runs back, turning in place between runs), steered from its
    TRUE pose; encoders carry systematic and random errors; sonars are cast as
    cone rays with specular bounces; camera frames show the lit lamps.

    \b
    Streams (ROS 2 messages, zstd chunks, log time = simulation time from 0):
      /joint_states              wheel angles (rad), robot rate
      /odom                      dead reckoning from the encoders (odom -> base_link)
      /ground_truth/odom         true pose (map -> base_link)
      /sonar/s00 .. /sonar/s15   Range, a whole ring per stamp, sonar rate (or one
                                 sonar every sonar.firing_gap_s, a Pioneer's ring)
      /ceiling_camera/image_raw  mono8 frames, + /ceiling_camera/camera_info
      /tf                        odom -> base_link (the dead reckoning), robot rate
      /tf_static                 base_link -> sonar_NN, ceiling_camera
      /sim/events                JSON of run starts/ends, lamp failures, bumps
      /sim/world                 walls and lamps as markers (Foxglove), at t=0
    MCAP metadata 'fuzzyslam.world' and 'fuzzyslam.scenario' (written first) hold
    the world and the scenario with its events and resolved config. The messages
    follow ROS 2 Humble's definitions, or Jazzy's with output.ros_distro: jazzy in
    the config (Range then carries its variance); so do run's and map's MCAPs.

    --truth-tum FILE also writes the true trajectory (the poses of /ground_truth/odom)
    as TUM, for evo (evo_ape tum FILE OUTDIR/trajectory.tum).

    Prints a JSON summary on stdout: file, duration, message counts per topic,
    dead-reckoning end/max error, fraction of frames with >= 2 lamps in view
    (overall and while all lamps are on), sonar no-echo fraction. Progress goes
    to stderr. Same config and seed give a byte-identical file; an error leaves
    no partial file (exit 3 on bad input).
    """
    from fuzzyslam.sim.stage import run

    emit(run(config, output, seed, preview, truth_tum))
