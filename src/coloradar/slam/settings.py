"""Settings of radar SLAM (one frozen record; every field documented and checked)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..errors import SettingsError

__all__ = ["SlamSettings"]


@dataclass(frozen=True)
class SlamSettings:
    """What :func:`~coloradar.slam.slam_from_clouds` does, and with which thresholds.

    Front end
    ---------
    smooth_frontend
        Smooth the radar-inertial filter's poses with the later measurements too
        (Rauch–Tung–Striebel, :mod:`coloradar.odometry.smoother`; it sets the front end's
        ``RioConfig.smooth``) before the keyframes' motions become odometry factors. SLAM
        runs offline, so nothing is lost by waiting for the later frames; a filter's pose
        at a keyframe has only seen the earlier ones, and its error over the few seconds
        between keyframes is what loops between laps cannot see. On by default: on the
        tuning runs (seeds 101–130 single chip, 101–124 cascade; docs/slam.md) it took the
        single chip's mean SLAM ATE from 2.71 to 1.80 cm (every run better) and the
        cascade's from 1.56 to 1.02 cm (every run better).

    Keyframes and submaps
    ---------------------
    keyframe_distance, keyframe_angle_deg
        A new keyframe when the odometry has moved this far [m] or turned this much [deg]
        since the last one.
    submap_window
        A keyframe's submap holds the static points of the frames within this many seconds
        of it (both sides) [s], moved into the keyframe's base frame with the odometry.
    submap_voxel
        Voxel edge of a submap (points, intensities and covariances averaged per voxel) [m].
    max_range, min_range
        Points used, by range from the radar [m].
    static_threshold
        A point is static when its range rate is within this of what a static point at its
        place shows under the frame's ego-velocity [m/s]; None: the ego-velocity estimator's
        inlier threshold.
    range_std, azimuth_std_deg, elevation_std_deg
        Point accuracy (one standard deviation) in range [m] and angle [deg]; None: from the
        radar (half a range bin; the angle accuracy of its array, see :mod:`.submaps`).

    Registration (small_gicp)
    -------------------------
    registration
        ``"GICP"`` (small_gicp's VGICP, tried on the known-transform test of
        ``tests/test_slam.py``, ended 0.03–3 m off depending on its voxel size, so it is not
        offered).
    max_correspondence
        Largest point distance paired during registration [m].
    inlier_distance
        A point counts for fitness and overlap within this of the other submap [m].
    refine_odometry
        Also register each keyframe's submap to the previous one and add that as a second
        relative-pose factor between them, kept when it passes the chi-square test against
        the odometry's motion (scan-to-submap refinement of the odometry). The two submaps
        share most of their frames, so the factor is not independent of the odometry's; it
        weighs the step where the scene pins it. On by default: on the tuning runs (seeds
        101–130 single chip, 101–124 cascade; docs/slam.md) it took the single chip's SLAM
        ATE down on 10 of 30 runs (courtyards by 0.4 cm on average), up on 2, and left the
        cascade's as it was (1 run better, none worse).
    disjoint_registration
        Where to register each keyframe's submap to that of the first keyframe ``2 ·
        submap_window`` later (the two share no frame) and add it as a gated relative-pose
        factor with the loop factors' floors, holding the odometry's drift between loops
        (:func:`coloradar.slam.system._disjoint_edges`): ``"elevation"`` for a radar with at
        least 3 elevation rows (the cascade; the single chip's registrations of submaps seen
        seconds apart are too coarse: the factors made its SLAM worse on 4 of 10 tuning runs
        and better on 5), ``"always"`` or ``"never"``.

    Scale
    -----
    estimate_scale
        Measure the odometry's scale by registering keyframes whose submaps share no frame
        (:mod:`.scale`) and apply it to the odometry factors.
    scale_common_radius
        Only the points of each submap within this of the other (placed by the odometry) are
        registered [m].
    scale_probe
        Each pair is registered from the odometry's relative pose with its translation
        shortened and lengthened by this share.
    scale_agreement
        A pair whose two registrations differ by more than this in scale is not used.
    scale_min_pairs, scale_max_std
        The scale is applied only when at least this many pairs measured it, to this standard
        error.
    scale_rebuild
        When a scale is applied, build the submaps again with the odometry so scaled, so that
        loops and the map use submaps at the graph's scale.

    Loop closure
    ------------
    loop_min_separation
        Path length between two keyframes before they may close a loop [m].
    loop_search_radius
        Candidates are keyframes whose odometry positions lie within this of each other, plus
        ``loop_gate_sigma`` standard deviations of the odometry's relative uncertainty [m].
    loop_gate_sigma
        That many standard deviations of the relative position uncertainty.
    loop_reverse_along_std
        A loop between keyframes whose headings differ by more than 90° (the place seen from
        the other way) gets this standard deviation [m] added along the direction of travel
        (:func:`.loops.reverse_release`; 0: none).
    descriptor_rings, descriptor_sectors, descriptor_range
        Scan-context grid (rings × sectors out to ``descriptor_range`` [m]).
    max_descriptor_distance
        Candidates whose descriptors differ more than this (0 = identical, 1 = unrelated) are
        not registered.
    min_fitness, min_overlap
        Verification: share of the candidate's points within ``inlier_distance`` of the
        other submap after registration, and the smaller of that share both ways.
    gate_probability
        Chi-square quantile of the Mahalanobis test of a loop against the odometry (the
        registered relative pose against the odometry's, with their covariances), and of the
        consistency test of each loop's residual after optimisation.
    loop_translation_std, loop_rotation_std_deg
        Floors of a loop factor's standard deviation [m], [deg] (added to the registration's).
    registration_cov_scale
        Factor on the registration covariance computed from the per-point covariances
        (neighbouring points of a submap are not independent).
    robust_kernel
        ``"cauchy"``, ``"huber"`` or ``"none"``: the loop factors' M-estimator.
    odometry_floor_translation, odometry_floor_rotation_deg
        Standard deviations added to every odometry factor (per keyframe step) [m], [deg].
    odometry_cov_scale
        Factor on the filter's relative covariance between keyframes (odometry factors and
        the loop search's gate).
    max_loop_candidates
        At most this many candidates (the best descriptors) are registered per keyframe.

    Map
    ---
    map_kind
        What ``run_slam`` writes as ``map.ply``: ``"occupancy"`` (default; a probabilistic
        occupancy map of every frame placed by the optimised trajectory,
        :mod:`coloradar.mapping`: free space carved by the rays, ghosts outvoted) or
        ``"points"`` (the keyframes' submaps, :attr:`SlamResult.map_points`, as before issue 40).
    map_voxel
        Voxel edge of the map [m] (both kinds).
    map_min_keyframes
        A voxel of the point map is kept only when the submaps of this many keyframes put a
        point in it.
    """

    keyframe_distance: float = 1.0
    keyframe_angle_deg: float = 15.0
    submap_window: float = 3.0
    submap_voxel: float = 0.1
    max_range: float = 12.0
    min_range: float = 0.4
    static_threshold: float | None = None
    smooth_frontend: bool = True
    range_std: float | None = None
    azimuth_std_deg: float | None = None
    elevation_std_deg: float | None = None
    registration: str = "GICP"
    max_correspondence: float = 0.6
    inlier_distance: float = 0.3
    refine_odometry: bool = True
    disjoint_registration: str = "elevation"
    estimate_scale: bool = True
    scale_common_radius: float = 2.0
    scale_probe: float = 0.03
    scale_agreement: float = 0.005
    scale_min_pairs: int = 10
    scale_max_std: float = 0.003
    scale_rebuild: bool = True
    loop_min_separation: float = 8.0
    loop_search_radius: float = 2.0
    loop_gate_sigma: float = 3.0
    loop_reverse_along_std: float = 0.3
    descriptor_rings: int = 10
    descriptor_sectors: int = 36
    descriptor_range: float = 10.0
    max_descriptor_distance: float = 0.6
    min_fitness: float = 0.5
    min_overlap: float = 0.3
    gate_probability: float = 0.999
    loop_translation_std: float = 0.05
    loop_rotation_std_deg: float = 1.0
    registration_cov_scale: float = 10.0
    robust_kernel: str = "cauchy"
    odometry_floor_translation: float = 0.005
    odometry_floor_rotation_deg: float = 0.1
    odometry_cov_scale: float = 1.0
    max_loop_candidates: int = 2
    map_kind: str = "occupancy"
    map_voxel: float = 0.15
    map_min_keyframes: int = 3

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or v is None or isinstance(v, str):
                continue
            if not (np.isfinite(v) and v >= 0):
                raise SettingsError(f"SlamSettings.{f.name} must be a finite number >= 0, "
                                    f"got {v!r}")
        for name in ("keyframe_distance", "submap_voxel", "max_correspondence", "inlier_distance",
                     "descriptor_range", "max_range", "map_voxel"):
            if not getattr(self, name) > 0:
                raise SettingsError(f"SlamSettings.{name} must be positive")
        if self.registration != "GICP":
            raise SettingsError(f"SlamSettings.registration must be 'GICP', got "
                                f"{self.registration!r}")
        if self.disjoint_registration not in ("elevation", "always", "never"):
            raise SettingsError(f"SlamSettings.disjoint_registration must be 'elevation', "
                                f"'always' or 'never', got {self.disjoint_registration!r}")
        if self.map_kind not in ("occupancy", "points"):
            raise SettingsError(f"SlamSettings.map_kind must be 'occupancy' or 'points', got "
                                f"{self.map_kind!r}")
        if self.robust_kernel not in ("cauchy", "huber", "none"):
            raise SettingsError(f"SlamSettings.robust_kernel must be 'cauchy', 'huber' or "
                                f"'none', got {self.robust_kernel!r}")
        if not 0 <= self.scale_probe < 1:
            raise SettingsError("SlamSettings.scale_probe is a share in [0, 1)")
        if not 0 < self.gate_probability < 1:
            raise SettingsError("SlamSettings.gate_probability must be in (0, 1)")
        if self.descriptor_rings < 1 or self.descriptor_sectors < 4:
            raise SettingsError("SlamSettings: at least 1 descriptor ring and 4 sectors")
        if not 0 <= self.min_fitness <= 1 or not 0 <= self.min_overlap <= 1:
            raise SettingsError("SlamSettings.min_fitness and min_overlap are shares in [0, 1]")
