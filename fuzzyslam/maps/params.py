"""Parameters of the fuzzy global and local maps (docs/models.md sec. 5-8).

Sonar evidence constants (docs/models.md sec. 5, Oriolo, Ulivi & Vendittelli 1997) and why:

- ``k_occupied`` = 0.6, ``k_empty`` = 0.4: one reading is weak evidence (k < 1), so a
  cell needs several agreeing readings to become certain; k_O + k_E <= 1 keeps the
  reading's mass function valid where the occupied arc and the empty ramp overlap.
  Occupied evidence is stronger than empty because a short echo is rarely wrong while a
  long one is often specular (a missed wall: Moravec 1990).
- ``range_tolerance`` dr = 0.10 m: half-width of the occupied arc; about 4 sigma of the
  Polaroid's 1 % range error at 1-2 m plus its 1-inch quantisation, and one cell.
- ``reliability_range`` rho_h = 1 m: distance reliability of occupied evidence,
  d(rho) = 1 / (1 + (rho/rho_h)^2). The beam's footprint grows with rho (the echo's source
  is less certain) and long readings are mostly multipath (bounced) echoes; d is 0.5 at
  1 m, 0.2 at 2 m, 0.02 at 6.5 m. Measured on the simulated paper scenario from true
  poses: rho_h = 3 / 1.5 / 1 / 0.8 m gave wall precision 0.65 / 0.69 / 0.75 / 0.78 at
  recall 0.91-1.0; 1 m keeps the corridor references best.
- ``empty_reliability_range`` rho_E = 3 m: the same for empty evidence.
- ``empty_reach`` = 0.9 m: empty evidence only up to 0.9 m from the sensor. In a
  specular corridor the oblique sonars miss the walls and return long bounced echoes
  whose cones cross the walls (a 45-degree sonar meets a wall 0.775 m away at 1.1 m); their
  empty evidence erased the walls (recall 0.45 with no limit, 0.91 at 1.2 m, 1.0 at
  0.9 m, paper scenario, true poses). Raise it for open spaces with rough walls.
- ``no_echo_empty`` = 0.05 and ``no_echo_reach`` = 0.6 m: a max-range reading (no echo)
  says little in a specular corridor (a wall at more than the critical incidence does not
  echo: in a 2 m corridor the 45-degree sonars miss walls 1.1 m away), so it gives only
  very weak empty evidence, and only nearer than the closest wall of a corridor.
- ``angular_exponent`` p = 8: angular weight 1 - |phi/w|^p, flatter than Oriolo et al.'s
  parabola (p = 2). With specular walls the echo comes from the part of the cone at
  normal incidence, often its edge, which the parabola all but ignores. Measured: FLM
  wall direction error on analytic rings 0.51 deg mean with p = 8 against 0.98 with
  p = 2; the FGM's corridor references are unchanged (within 0.1 deg) and wall precision
  drops from 0.75 to 0.72 (paper scenario, true poses).
- ``flm_wall_threshold`` = 0.02: an FLM holds one ring, so every cell with evidence votes
  in its Hough transform (``wall_threshold`` = 0.3 is for the FGM's accumulated evidence).
- ``hough_refine`` = tls for the FGM's corridors (long straight walls: the TLS fit of
  the supporting cells gave 0.00-0.12 deg on the paper scenario against 0.05-0.36 deg
  with the parabola), ``flm_hough_refine`` = parabolic for FLMs (short arcs tangent to
  the walls bias a line fit: 0.8 deg against 2.0 deg mean error on analytic rings).
- ``flm_refine`` = tangent (beyond the paper, :mod:`fuzzyslam.maps.tangent`): the FLM's
  Hough direction is refined by a least-squares fit of the walls' common tangent to the
  ring's echo circles. Simulated paper log, rings in corridors: 1.18 deg mean |error|,
  std 1.57 deg per ring against 2.23 / 2.81 for the Hough alone; 8 rings placed by
  odometry (``build_flm_rings``): 0.35 / 0.44 deg. ``tangent_tolerance`` = 6 cm: outlier
  cut on the range residual (about 5 sigma of 1 % noise + 1-inch quantisation at 1 m;
  3 cm gave 1.48, 9 cm 1.38 deg); ``tangent_max_incidence_deg`` = 20: a wall farther
  than this outside the cone does not echo (the critical angle, docs/models.md sec. 11);
  ``tangent_max_shift_deg`` = 10: a fit that moves farther from the Hough peak is
  refused (the Hough angle is kept, flagged ambiguous); ``tangent_max_sigma_deg`` = 3:
  a fit less certain than this flags the ring ambiguous (2 deg flagged 12 % of good
  mid-corridor rings, 3 deg 10 %, 4 deg 7 % but let 1.7 % gross errors through);
  ``tangent_second_ratio`` = 0.5: the echoes left out of the fit that support the
  Hough's second direction flag a junction when they number at least half the fit's
  (8-ring FLMs 0.5-1 m from a corridor end: unflagged wrong-corridor directions 20 % ->
  4 %; mid-corridor rings unaffected).
- ``segment_end_trim`` = 0.5 m: corridor regions stop short of the junctions, whose
  cells carry the next corridor's walls.
- ``forgetting_gamma``: alpha = 1 - gamma * m(conflict) (docs/models.md sec. 6).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class MapParams:
    """Fuzzy grid maps from sonar evidence, Smets' calculus, forgetting, Hough references."""

    resolution: float = field(default=0.10, metadata={"min": 0.01, "max": 1.0})
    margin: float = field(default=2.0, metadata={"min": 0.0, "max": 20.0})
    flm_cells: int = field(default=41, metadata={"min": 5, "max": 1001})
    freeze_run: int = field(default=4, metadata={"min": 1})
    # --- per-reading evidence (docs/models.md sec. 5) ---
    k_occupied: float = field(default=0.6, metadata={"min": 0.0, "max": 1.0})
    k_empty: float = field(default=0.4, metadata={"min": 0.0, "max": 1.0})
    range_tolerance: float = field(default=0.10, metadata={"min": 0.01, "max": 2.0})
    angular_exponent: float = field(default=8.0, metadata={"min": 0.5, "max": 50.0})
    reliability_range: float = field(default=1.0, metadata={"min": 0.1, "max": 100.0})
    empty_reliability_range: float = field(default=3.0, metadata={"min": 0.1, "max": 100.0})
    empty_reach: float = field(default=0.9, metadata={"min": 0.0, "max": 1000.0})
    no_echo_empty: float = field(default=0.05, metadata={"min": 0.0, "max": 1.0})
    no_echo_reach: float = field(default=0.6, metadata={"min": 0.0, "max": 50.0})
    # --- combination (docs/models.md sec. 6) ---
    forgetting_gamma: float = field(default=1.0, metadata={"min": 0.0, "max": 1.0})
    # --- trajectory interpolation ---
    max_pose_gap: float = field(default=1.0, metadata={"min": 0.01, "max": 100.0})
    # --- Hough and references (docs/models.md sec. 8-9) ---
    wall_threshold: float = field(default=0.3, metadata={"min": 0.0, "max": 1.0})
    flm_wall_threshold: float = field(default=0.02, metadata={"min": 0.0, "max": 1.0})
    hough_theta_step_deg: float = field(default=0.5, metadata={"min": 0.05, "max": 5.0})
    hough_refine: str = field(default="tls", metadata={"choices": ["parabolic", "tls"]})
    flm_hough_refine: str = field(default="parabolic", metadata={"choices": ["parabolic", "tls"]})
    flm_refine: str = field(default="tangent", metadata={"choices": ["hough", "tangent"]})
    tangent_tolerance: float = field(default=0.06, metadata={"min": 0.005, "max": 1.0})
    tangent_max_incidence_deg: float = field(default=20.0, metadata={"min": 0.0, "max": 80.0})
    tangent_max_shift_deg: float = field(default=10.0, metadata={"min": 0.1, "max": 90.0})
    tangent_max_sigma_deg: float = field(default=3.0, metadata={"min": 0.01, "max": 90.0})
    tangent_second_ratio: float = field(default=0.5, metadata={"min": 0.0, "max": 100.0})
    range_noise_frac: float = field(default=0.01, metadata={"min": 0.0, "max": 0.5})
    range_quantum: float = field(default=0.0254, metadata={"min": 0.0, "max": 1.0})
    ambiguity_ratio: float = field(default=0.85, metadata={"min": 0.0, "max": 1.0})
    ambiguity_separation_deg: float = field(default=20.0, metadata={"min": 1.0, "max": 89.0})
    segment_min_length: float = field(default=2.0, metadata={"min": 0.1, "max": 100.0})
    segment_turn_deg: float = field(default=10.0, metadata={"min": 0.5, "max": 90.0})
    segment_band: float = field(default=1.6, metadata={"min": 0.1, "max": 20.0})
    segment_end_trim: float = field(default=0.5, metadata={"min": 0.0, "max": 20.0})
    segment_merge_distance: float = field(default=0.8, metadata={"min": 0.0, "max": 20.0})
    # a reference whose strongest wall line holds less than this (m of wall at full
    # belief) is flagged ambiguous (no heading fix from it): a room, a stub or a doorway
    # seen from the path, not a corridor; 0: no bound
    reference_min_strength: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})

    def __post_init__(self) -> None:
        if self.k_occupied + self.k_empty > 1.0 + 1e-9:
            raise ValueError(
                f"k_occupied + k_empty must be <= 1 (got {self.k_occupied + self.k_empty:g}): "
                "a reading's masses m(E) + m(O) may not exceed 1"
            )
        if self.flm_cells % 2 == 0:
            raise ValueError(
                f"flm_cells must be odd (robot on the centre cell), got {self.flm_cells}"
            )
