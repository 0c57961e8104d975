"""Parameters of heading and pose fixes from the frozen fuzzy map (docs/models.md sec. 9-10)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class FixParams:
    """Heading fixes (the paper), full-pose fixes and change detection (beyond it)."""

    mode: str = field(default="heading", metadata={"choices": ["none", "heading", "pose"]})

    # --- heading fixes (docs/models.md sec. 9) ---
    # R = sigma^2 of one heading measurement: the scatter of FLM-vs-reference headings.
    # Measured against the simulator's truth on paper.yaml (runs 5-6, seed 0, 594 fixes in
    # corridors): mean -0.01 deg, std 1.49 deg, errors of successive rings uncorrelated
    # (lag-1 autocorrelation 0.07); the paper reports mean 1.0, std 0.66 deg
    sigma_heading_deg: float = field(default=1.5, metadata={"min": 0.01, "max": 90.0})
    # chi-square gate on the heading innovation, 1 dof (99 %: 6.63)
    gate_chi2: float = field(default=6.63, metadata={"min": 0.1})
    # Hough peak strength below which a FLM gives no usable wall direction
    min_strength: float = field(default=0.0, metadata={"min": 0.0})
    # reduce theta mod pi/2 instead of mod pi (only where every wall meets the others at
    # right angles; the paper world has a 70-degree corridor, so off by default)
    right_angles: bool = False
    # refuse when the two candidate headings nearest the prediction are both within this
    # many standard deviations sqrt(P_tt + R) of it
    ambiguity_sigmas: float = field(default=3.0, metadata={"min": 0.5, "max": 20.0})
    # corners and junctions (outside every corridor region, or in regions whose angles
    # differ): with a margin > 0 (m), the regions within it all offer their reference
    # angle and the prediction picks (refused when two are plausible); 0: skip the fix
    junction_margin: float = field(default=2.0, metadata={"min": 0.0, "max": 10.0})
    # R of such a fix: FLM walls near a corner are shorter and mixed (measured: std 1.8
    # deg, mean -0.2 deg at corners, 198 fixes, same run as sigma_heading_deg)
    # at a junction, accept a FLM with two wall directions (its strongest wall is one of
    # the competing corridors'; a wrong pick is far off and gated) instead of skipping it
    # as ambiguous_wall. Measured on paper_bumps.yaml seeds 0-2 (heading fixes from t=0):
    # max position error 34 / 33 / 31 cm -> 9 / 8 / 12 cm, duplicate lamps 3 / 3 / 8 ->
    # 0 / 0 / 5 (a bump while turning in a corner was left uncorrected for seconds)
    junction_walls: bool = True
    sigma_junction_deg: float = field(default=2.0, metadata={"min": 0.01, "max": 90.0})
    # recovery from an unseen heading jump (a bump): after this many consecutive gated
    # single-ring fixes whose measurements agree (recover_spread_p), the heading variance
    # is inflated by the squared innovation (ekf.inflate_robot) and the fix applied; 0:
    # never. Rings forming no fix, and rings at oblique junctions, are skipped
    # (fixes/bump_recovery.py recovery_streak)
    recover_after: int = field(default=3, metadata={"min": 0})
    # a fix with NIS above this (1 dof, 95 %: 3.84) or gated marks the pose suspect: no
    # new lamp is created until an applied fix agrees again and while the latest ring
    # confirms nothing (duplicates after a bump; HeadingFixAid._update_suspicion)
    suspect_chi2: float = field(default=3.84, metadata={"min": 0.1})
    # the streak's measurements agree when, relative to the dead-reckoning heading (a bump
    # is a constant offset), their scatter is within the chi-square quantile with
    # recover_after - 1 dof at this probability, each ring weighted by its R (replaces a
    # 3-deg max-min range, which 3 rings of 1.5 deg noise exceed one time in three).
    # Measured on paper_bumps.yaml seeds 0-4 (phase D, heading fixes from t=0), together
    # with the skipped rings and the oblique-junction rule: worst max axis error 7.8 / 8.7
    # / 10.1 / 18.1 / 15.0 cm -> 7.3 / 7.4 / 6.5 / 9.2 / 6.6 cm, false recoveries 2 / 2 /
    # 0 / 2 / 2 -> 0, latency of the 30 true ones at most 1.2 s (was 3.55 s); without the
    # oblique rule 24 false recoveries (up to 19.7 cm)
    recover_spread_p: float = field(default=0.99, metadata={"min": 0.5, "max": 0.999999})
    # a streak is no bump evidence when its innovation exceeds this (deg): beyond half
    # the angle between a building's corridors a "consistent" streak is as likely the
    # next corridor's walls (a right-angled junction) as a bump; 180: no bound
    recover_max_deg: float = field(default=180.0, metadata={"min": 0.0, "max": 180.0})
    # the streak's rings all lie within this many seconds (skipped rings in between)
    recover_window_s: float = field(default=2.0, metadata={"min": 0.0, "max": 30.0})
    # the sequential test of a heading jump (fixes/bump_recovery.py jump_log_odds, Wald's
    # SPRT with a Bayes factor): a recovery is also due, before recover_after rings, when
    # the corridor rings since the last agreeing fix favour "the heading jumped" over "it
    # did not" by at least 1 / recover_alpha; 0: off (recover_after 0 turns both off).
    # One ring carries at most 1 / eps (below), 2300 for the tightest: 1 / alpha = 5000
    # lets no ring decide alone (one whose wall fit is tight and 8 deg off was measured on
    # a seed of the quick world, near a junction: a recovery at once turned a correct
    # heading), while a second ring, or earlier ambiguous_wall rings leaning the same
    # way, decide. Measured on paper_bumps.yaml seeds 0-4 (heading fixes from t = 0):
    # see docs/models.md sec. 9
    recover_alpha: float = field(default=2e-4, metadata={"min": 0.0, "max": 0.5})
    # the corridor rings' gross-error rates in the test's likelihoods, (1 - eps) N(v; mean,
    # s^2) + eps / period: the fraction of rings more than 5 s from the simulator's true
    # heading (paper log, calibration off, phases C and D of seeds 0-2 away from the bumps;
    # the rule of three, 3 / n, where none was): a formed fix whose wall fit is within
    # sigma_heading_deg (s = sigma_heading_deg): 0 of 7045 (3 / 7045); one with a looser
    # fit (s = its fit's sigma): 2 of 259; an ambiguous_wall ring's dominant wall in one
    # corridor (s = max(fit, sigma_heading_deg)): 0 of 774 (3 / 774). Seeds 3-4 alike: 0
    # of 4719, 1 of 202, 0 of 498. Junction rings (223 of 3805, in agreeing runs) are left
    # to the streak rule (bump_recovery's docstring)
    recover_outlier_fit: float = field(default=4.3e-4, metadata={"min": 1e-9, "max": 1.0})
    recover_outlier_loose: float = field(default=7.7e-3, metadata={"min": 1e-9, "max": 1.0})
    recover_outlier_ambiguous: float = field(default=3.9e-3, metadata={"min": 1e-9, "max": 1.0})

    # --- multi-ring FLM heading fixes (beyond the paper; fixes.heading, maps.flm) ---
    # rings fused into the FLM the wall direction is measured on, placed by dead reckoning
    # (EkfSlam.odometry_pose) in the newest ring's frame; 1: the paper's single-ring FLM.
    # Measured on paper.yaml seeds 0 / 1 / 2, runs 5-6, accepted fixes, error against truth
    # (mean |error| / std, deg): 1 ring 1.20 / 1.54, 1.20 / 1.51, 1.20 / 1.53; 10 rings
    # (every 5) 0.37 / 0.49, 0.34 / 0.42, 0.33 / 0.44; 4 rings 0.58 / 0.73 (seed 0); 8 rings
    # 0.40 / 0.51, 0.36 / 0.45, 0.35 / 0.45; 12 rings 0.33 / 0.43, 0.33 / 0.41, 0.31 / 0.42
    # (every 12 rings: 3 s between fixes)
    flm_rings: int = field(default=10, metadata={"min": 1, "max": 64})
    # only rings of the last flm_window_s seconds are fused (10 rings at 4 Hz: 2.25 s)
    flm_window_s: float = field(default=3.0, metadata={"min": 0.0, "max": 30.0})
    # one multi-ring fix every this many rings (0: every flm_rings rings, disjoint windows);
    # with overlapping windows (flm_fix_every < flm_rings) the fixes share rings, so R is
    # inflated by flm_rings / flm_fix_every (the information per ring stays that of one fix).
    # Chosen on seeds 0-2 (10 rings; every 10 / 5 / 2): fix accuracy alike; phase D worst
    # max axis error 9.8 / 9.1 / 9.0, 7.8 / 8.7 / 10.2, 7.5 / 10.2 / 6.3 cm (1 ring: 8.9 /
    # 7.6 / 11.3); every lamp off (pose mode) mean 2.9 / 2.4 / 1.6, 1.3 / 2.8 / 1.2, 1.4 /
    # 2.8 / 1.5 cm (1 ring: 2.0 / 2.3 / 2.1); real-time factor of run (heading, seed 0)
    # 124 / 116 / 98 (1 ring: 130), pose mode 111 / 104 / 89: every 5
    flm_fix_every: int = field(default=5, metadata={"min": 0, "max": 64})
    # windows in metres of travel (fixes.multi_ring) [ours]: what a window sees of the
    # walls grows with the robot's travel, not with its rings (a ring every 9 cm in one
    # building, every metre in another). flm_window_m > 0: the window keeps only rings
    # within this much dead-reckoned travel of the newest (also at most flm_rings, within
    # flm_window_s); flm_fix_travel > 0: a fix is formed once the robot has travelled this
    # far since the last one (instead of every flm_fix_every rings), with R inflated by
    # flm_window_m / flm_fix_travel (overlapping windows count each metre once)
    flm_window_m: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    flm_fix_travel: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    # a multi-ring fix's noise from its own wall fit [ours] (with the tangent refinement):
    # q = sigma_fit * max(1, Birge ratio) * sqrt(rings in the window), the fit's standard
    # deviation scaled by how far its residuals exceed the range noise model (doors,
    # clutter, rooms) and by sqrt(K) because the K rings of a window re-measure the same
    # walls (their errors are common, not independent). Measured on two real building
    # logs (4 m windows placed by truth, error against the corridor's reference): the
    # rms error is 1.4-2.5 q for q up to 1 deg in both, and beyond 1 deg the gross
    # (> 10 deg) errors rise to 40-60 %. So sigma = max(sigma_flm_deg, flm_fit_scale * q)
    # (times the overlap inflation), and a window with q above flm_fit_max_deg forms no
    # fix (reason loose_fit). Off: flm_fit_sigma's rule (R raised to the model's sigma)
    flm_fit_scatter: bool = False
    flm_fit_scale: float = field(default=2.0, metadata={"min": 0.0, "max": 100.0})
    flm_fit_max_deg: float = field(default=1.0, metadata={"min": 0.0, "max": 90.0})
    # R = sigma^2 of one multi-ring fix in a corridor (disjoint windows; the measured std is
    # 0.40-0.49 deg); at a junction sigma_junction_deg * sigma_flm_deg / sigma_heading_deg
    sigma_flm_deg: float = field(default=0.5, metadata={"min": 0.01, "max": 90.0})
    # scale R up by (fit sigma / sigma_flm_deg)^2 when the wall's tangent fit reports a
    # standard deviation above sigma_flm_deg (a loose fit weighs less; measured: the fit's
    # sigma is at least 0.35 deg, above 0.7 for 10 % of the windows, whose errors are larger)
    flm_fit_sigma: bool = True

    # --- the wall direction a heading fix measures (docs/models.md sec. 9) ---
    # flm: the paper's Hough peak of the fuzzy local map (sonar, and the paper scenario);
    # scan_lines: straight segments fitted to a laser scan's end points, one fix per scan
    # (fixes.scan_lines, fixes.scan_heading; a log read with --ranges scan)
    heading_source: str = field(default="flm", metadata={"choices": ["flm", "scan_lines"]})
    # points per local line test, and the largest spread across (m) of a straight run
    scan_line_points: int = field(default=5, metadata={"min": 3, "max": 64})
    scan_line_tolerance: float = field(default=0.03, metadata={"min": 0.001, "max": 1.0})
    # neighbouring end points farther apart than this (m) are not on one wall
    scan_line_gap: float = field(default=0.5, metadata={"min": 0.01, "max": 10.0})
    # shortest segment (m), and the least wall (m) a family must hold to give a fix
    scan_line_min_length: float = field(default=0.5, metadata={"min": 0.0, "max": 20.0})
    scan_line_min_support: float = field(default=1.0, metadata={"min": 0.0, "max": 100.0})
    # straightness of a real wall (deg, per segment), added to the fit's own variance
    scan_line_wall_sigma_deg: float = field(default=0.5, metadata={"min": 0.0, "max": 10.0})
    # scatter of one scan's wall direction that its segments share (deg), added to R
    scan_line_sigma_deg: float = field(default=1.2, metadata={"min": 0.0, "max": 10.0})
    # least half-width (deg) of the window around the expected wall direction
    scan_line_gate_deg: float = field(default=3.0, metadata={"min": 0.1, "max": 45.0})

    # --- full-pose fixes (docs/models.md sec. 10) ---
    # also apply the Hough heading fixes in pose mode (the match leaves the heading free)
    pose_with_heading: bool = True
    pose_gate_chi2: float = field(default=11.34, metadata={"min": 0.1})  # 3 dof, 99 %
    # Olson's blur of the FGM's occupied mass (m): the width of the score's basin
    pose_blur: float = field(default=0.10, metadata={"min": 0.0, "max": 1.0})
    # weight of the conflict m_E(FLM) m_O(FGM) (an empty cone through a wall)
    pose_conflict_weight: float = field(default=1.0, metadata={"min": 0.0, "max": 10.0})
    # weight of the conflict m_O(FLM) m_E(FGM) (an echo arc in free space: mostly the
    # arc's own angular spread, so weak evidence against a pose)
    pose_arc_conflict_weight: float = field(default=0.0, metadata={"min": 0.0, "max": 10.0})
    # weight of the empty-with-empty agreement (near constant, flattens the surface)
    pose_empty_weight: float = field(default=0.0, metadata={"min": 0.0, "max": 10.0})
    # search half-window: 3 sigma of the prediction, clipped to [min, max]
    pose_window_min: float = field(default=0.2, metadata={"min": 0.0, "max": 5.0})
    pose_window_max: float = field(default=0.5, metadata={"min": 0.0, "max": 5.0})
    pose_window_min_deg: float = field(default=2.0, metadata={"min": 0.0, "max": 45.0})
    pose_window_max_deg: float = field(default=6.0, metadata={"min": 0.0, "max": 45.0})
    # rotation step of the coarse search and of the fine one around the coarse peak
    pose_coarse_deg: float = field(default=1.0, metadata={"min": 0.01, "max": 10.0})
    pose_fine_deg: float = field(default=0.5, metadata={"min": 0.01, "max": 10.0})
    # likelihood exp((s - s_max) / temperature), s the explained fraction of the FLM's walls
    pose_temperature: float = field(default=0.02, metadata={"min": 1e-4, "max": 1.0})
    # inflation of the surface's covariance for the correlation of successive rings' errors
    # (measured against truth: 4.5 cm RMS per ring, autocorrelation 0.7 / 0.5 / 0.3 / 0.0
    # at lags 1 / 2 / 4 / 8 rings). Chosen on paper_dark.yaml seed 0, runs 5-6, 3-dof NEES
    # (before pose_map_sigma): 10.4 at 8, 5.5 at 32, 4.9 at 100
    pose_cov_scale: float = field(default=100.0, metadata={"min": 1.0, "max": 1000.0})
    # correlation length (m of travel) of successive matches' errors; > 0: the inflation
    # is that of exponentially correlated errors sampled s metres apart (s the travel
    # since the last applied match), coth(s / 2L) (the sum of their autocorrelations,
    # Bar-Shalom et al. sec. 8.2), at most pose_cov_scale (fixes.pose_match.cov_inflation);
    # 0: always pose_cov_scale (rings at a fixed rate)
    pose_corr_distance: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    # accuracy of the frozen map itself (m, 1 sigma): a match is skipped ("prior_better")
    # while the filter's position sigma (largest axis) is below it, since the map's error
    # is the same ring after ring and would be averaged in as if it were information.
    # Measured (paper.yaml, seeds 0-2, runs 5-6, 3-dof NEES against truth): 8 lamps lit
    # 5.5 / 19.1 / 1.9 at 0 -> 1.6 / 2.5 / 1.2 at 0.02 (errors 0.9 / 2.0 / 0.6 cm -> 0.7 /
    # 1.3 / 0.8 cm); every lamp off 4.7 / 8.5 / 4.1 -> 3.7 / 3.6 / 3.1
    pose_map_sigma: float = field(default=0.02, metadata={"min": 0.0, "max": 1.0})
    # floor of the measurement's standard deviations (the grid's own quantisation)
    pose_min_sigma: float = field(default=0.02, metadata={"min": 1e-4, "max": 1.0})
    pose_min_sigma_deg: float = field(default=0.25, metadata={"min": 1e-3, "max": 10.0})
    # an eigen-direction whose variance exceeds this fraction of the window's uniform
    # variance is unconstrained (e.g. along a corridor) and is given no information
    pose_degenerate_fraction: float = field(default=0.5, metadata={"min": 0.05, "max": 1.0})
    # a second separate mode holding more than this fraction of the likelihood: reject
    pose_max_second_mode: float = field(default=0.1, metadata={"min": 0.0, "max": 1.0})
    # FLM evidence: cells with m(O) or m(E) above this take part; fewer O cells: reject
    pose_min_mass: float = field(default=0.05, metadata={"min": 0.0, "max": 1.0})
    pose_min_occupied_cells: int = field(default=8, metadata={"min": 1})
    # relocalisation (fixes.pose_aid): a ring whose match mode lies on or beyond the
    # 3-sigma window is matched again over 3, 9, ... times wider windows, and after this many
    # consecutive gated matches agreeing on the correction of the dead reckoning the
    # robot covariance is inflated by the innovation and the match applied; 0: never
    pose_recover_after: int = field(default=0, metadata={"min": 0, "max": 100})
    # a ring is matched only once the robot has moved this far (m) or turned this much
    # (deg) since the last applied match (dead reckoning; 0: every ring). With errors
    # correlated over pose_corr_distance L, matches s apart carry tanh(s / 2L) / s of
    # information per metre (cov_inflation): L / 3 keeps 99 % of it
    pose_min_travel: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    pose_min_turn_deg: float = field(default=0.0, metadata={"min": 0.0, "max": 180.0})
    # windows of at most this many translations are correlated by one matrix product
    # for all rotations instead of one cv2.matchTemplate per rotation (the same sums,
    # rounded differently; measured 10x faster for a 5 x 5 window, slower beyond about
    # 13 x 13); 0: always matchTemplate
    pose_direct_shifts: int = field(default=0, metadata={"min": 0, "max": 10000})
    # match every n-th ring (amortises the cost)
    pose_every: int = field(default=1, metadata={"min": 1})

    # --- the live map: grid SLAM without a map (run --live-map; docs/models.md sec. 10b) ---
    # a narrow-beam ring's (a laser scan's) echo end points within this distance (m) are
    # the match template; a sonar ring's is its FLM. Measured on the CARMEN logs (laser,
    # mean position error against truth.tum, ACES / fr079, before the heading fixes of
    # live_right_angles): 8 m 2.81 / 0.31, 12 m 1.90 / 0.30 (the default), 20 m 1.88 / -
    # at twice the cost; the FLM's cells 3.06 / 0.22
    live_reach: float = field(default=12.0, metadata={"min": 1.0, "max": 100.0})
    # a laser's match covariance inflation in a live-map run, in place of pose_cov_scale
    # and pose_corr_distance: a match of end points against the keyframes before it
    # measures the pose relative to them, its error independent of the next one's (the
    # frozen map's error, the same ring after ring, is not there). Measured (as
    # live_reach): 1 gives 1.90 / 0.30 m, the laser preset's coth inflation 3.94 / 0.48 m.
    # A sonar ring's FLM match keeps pose_cov_scale and pose_corr_distance (with 1, the
    # Freiburg sonar runs were lost: 0.56-5.5 m aligned, against 0.22-0.41 m); 0: the
    # laser's keeps them too
    live_cov_scale: float = field(default=1.0, metadata={"min": 0.0, "max": 1000.0})
    # heading fixes from each scan's wall lines against the building's wall direction mod
    # 90 deg, learnt over the first live_reference_m of travel (a building whose walls
    # meet at right angles, seen by a laser; fixes.live_map.LiveRightAngleHeading)
    live_right_angles: bool = False
    live_reference_m: float = field(default=5.0, metadata={"min": 0.5, "max": 100.0})
    # their wall window's least half-width (deg), in place of scan_line_gate_deg: the
    # two families lie 90 deg apart, so a window of 10 deg takes walls back from a
    # heading drifted that far (a frozen map's references may lie at any angle). Measured
    # on ACES, laser, its odometry errors doubled (generalise.py double-4): 3 deg 2.57 m
    # mean position error, 2.7 deg mean heading error; 10 deg 0.58 m, 1.6 deg
    live_gate_deg: float = field(default=10.0, metadata={"min": 0.1, "max": 44.0})
    # close the live map's loops at the end of the run: a pose graph of its keyframes
    # (odometry and scan-match edges, loop edges where a keyframe comes back near an old
    # one) solved by least squares, written as trajectory_closed.tum
    # (fixes.live_map.KeyframeGraph, fixes.pose_graph); a laser's only (a sonar ring's
    # matches are too loose for it)
    live_close_loops: bool = True
    # ... and during the run too: when a keyframe's loop edge moves the graph's solution
    # by a cell or more, the keyframes take the solution's poses, the live map is fused
    # again from them, and the filter is moved onto the newest keyframe's
    # (fixes.live_map.LiveMapPoseAid; docs/models.md sec. 10b)
    live_close_online: bool = True

    # --- change detection (docs/models.md sec. 10) ---
    detect_changes: bool = True
    # conflict m_O(FLM) * m_E(FGM) above which a cell contradicts the map
    change_min_conflict: float = field(default=0.15, metadata={"min": 0.0, "max": 1.0})
    change_min_cells: int = field(default=3, metadata={"min": 1})
    # fragments closer than this many cells are one detection
    change_link_cells: int = field(default=1, metadata={"min": 0, "max": 10})
    # FGM free space is eroded by this many cells so that pose error does not fire at walls
    change_erode_cells: int = field(default=1, metadata={"min": 0, "max": 10})
    # no detection while the position is this uncertain (1-sigma, m)
    change_max_sigma: float = field(default=0.15, metadata={"min": 0.0})
