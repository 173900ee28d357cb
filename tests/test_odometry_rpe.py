"""RPE pose pairing: evo's rules (consecutive segments, all pairs), rpg_trajectory_evaluation's and
every-pose pairing, checked against brute-force loops written from the rules' statements, and
against hand-counted pairs."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _trajectories import wander as _wander
from coloradar.geometry import Trajectory
from coloradar.odometry import RPE_PAIRINGS, path_length, relative_pose_error, rpe_pairs


def _noisy(ref, seed=4):
    rng = np.random.default_rng(seed)
    n = len(ref)
    return Trajectory(ref.timestamps, ref.translations + rng.normal(scale=0.03, size=(n, 3)),
                      Rotation.from_rotvec(rng.normal(scale=0.02, size=(n, 3))) * ref.rotations,
                      "estimate")


def _brute_evo_consecutive(p, d):
    """evo ``-u m``: the first pose is a segment end; accumulate the step lengths; when the sum
    reaches d, that pose ends a segment and the sum restarts from 0. Consecutive ends form the
    pairs."""
    ends, acc = [0], 0.0
    for k in range(1, len(p)):
        acc += np.linalg.norm(p[k] - p[k - 1])
        if acc >= d:
            ends.append(k)
            acc = 0.0
    return list(itertools.pairwise(ends))


def _brute_evo_all_pairs(p, d, rel_tol=0.1):
    """evo ``--all_pairs``: for each i the j whose path length from i is nearest to d (the
    earlier on a tie), kept when within d·rel_tol of d."""
    pairs = []
    for i in range(len(p)):
        best, best_res, arc = None, np.inf, 0.0
        for j in range(i + 1, len(p)):
            arc += np.linalg.norm(p[j] - p[j - 1])
            if abs(arc - d) < best_res:
                best, best_res = j, abs(arc - d)
        if best is not None and best_res <= rel_tol * d:
            pairs.append((i, best))
    return pairs


def _brute_every_pose(p, d):
    pairs = []
    for i in range(len(p)):
        arc = 0.0
        for j in range(i + 1, len(p)):
            arc += np.linalg.norm(p[j] - p[j - 1])
            if arc >= d:
                pairs.append((i, j))
                break
    return pairs


def _errors(est, ref, pairs):
    """|t_E| and angle(E) of E = (ref_i⁻¹ ref_j)⁻¹ (est_i⁻¹ est_j), one 4x4 matrix at a time."""
    def mat(tr, k):
        m = np.eye(4)
        m[:3, :3] = tr.rotations[k].as_matrix()
        m[:3, 3] = tr.translations[k]
        return m

    te, re = [], []
    for i, j in pairs:
        e = np.linalg.inv(np.linalg.inv(mat(ref, i)) @ mat(ref, j)) @ (
            np.linalg.inv(mat(est, i)) @ mat(est, j))
        te.append(np.linalg.norm(e[:3, 3]))
        cos = np.clip((np.trace(e[:3, :3]) - 1) / 2, -1.0, 1.0)
        re.append(np.degrees(np.arccos(cos)))
    return np.array(te), np.array(re)


def _brute_rpg(p, d):
    """rpg_trajectory_evaluation's ``compute_comparison_indices_length``: for each i the j
    whose path length from i is nearest to d, kept when strictly within 0.2·d (the earlier on
    a tie); fewer than two pairs give none."""
    # As rpg does: distances from the start, one scan per pose (Python floats: fast enough).
    steps = [float(np.linalg.norm(p[k] - p[k - 1])) for k in range(1, len(p))]
    acc = [0.0]
    for x in steps:
        acc.append(acc[-1] + x)
    pairs = []
    for i, start in enumerate(acc):
        best, best_res = None, 0.2 * d
        for j in range(i, len(acc)):
            if abs(acc[j] - (start + d)) < best_res:
                best, best_res = j, abs(acc[j] - (start + d))
        if best is not None:
            pairs.append((i, best))
    return pairs if len(pairs) >= 2 else []


BRUTE = {"evo": _brute_evo_consecutive, "evo_all_pairs": _brute_evo_all_pairs,
         "every_pose": _brute_every_pose, "rpg": _brute_rpg}


@pytest.mark.parametrize("pairing", RPE_PAIRINGS)
@pytest.mark.parametrize("d", [0.5, 1.0, 2.5])
@pytest.mark.parametrize("pairs_from", [None, "reference", "estimate"])
def test_rpe_pairs_and_errors_match_a_brute_force_of_the_rule(pairing, d, pairs_from):
    ref = _wander()
    est = _noisy(ref)
    # Whose path picks the pairs: evo's default is the estimate, every_pose's the reference.
    by = pairs_from or ("reference" if pairing in ("every_pose", "rpg") else "estimate")
    expected = BRUTE[pairing]((ref if by == "reference" else est).translations, d)
    assert len(expected) > 5
    (res,) = relative_pose_error(est, ref, [d], pairing=pairing, pairs_from=pairs_from)
    assert res.pairing == pairing
    t = ref.timestamps
    got = list(zip(np.searchsorted(t, res.start_times), np.searchsorted(t, res.end_times),
                   strict=True))
    assert got == expected
    te, re = _errors(est, ref, expected)
    np.testing.assert_allclose(res.translation_errors, te, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.rotation_errors, re, rtol=1e-6, atol=1e-6)


def test_evo_pairs_on_a_straight_line_counted_by_hand():
    # Poses 0.4 m apart, d = 1 m: the path reaches 1.2 m at pose 3, restarts there, and so on.
    # evo's first segment starts at pose 0.
    p = np.zeros((13, 3))
    p[:, 0] = 0.4 * np.arange(13)
    i, j = rpe_pairs(path_length(p), 1.0, "evo")
    assert list(zip(i, j, strict=True)) == [(0, 3), (3, 6), (6, 9), (9, 12)]
    # A path shorter than d: pose 0 alone ends a segment, no pair.
    i, j = rpe_pairs(path_length(p[:3]), 1.0, "evo")
    assert i.size == 0
    i, j = rpe_pairs(path_length(p), 1.0, "every_pose")
    assert list(zip(i, j, strict=True)) == [(k, k + 3) for k in range(10)]
    # All pairs: 1.2 m (3 steps) and 0.8 m (2 steps) are both 0.2 m off d = 1 m, outside the
    # 10 % tolerance.
    i, j = rpe_pairs(path_length(p), 1.0, "evo_all_pairs")
    assert i.size == 0
    # 0.3 m apart: 3 steps (0.9 m) is the nearest, within a 15 % tolerance; the last poses
    # have no partner.
    i, j = rpe_pairs(path_length(p * 0.75), 1.0, "evo_all_pairs", tolerance=0.15)
    assert list(zip(i, j, strict=True)) == [(k, k + 3) for k in range(10)]


def test_rpe_pairing_is_checked():
    with pytest.raises(ValueError, match="pairing"):
        rpe_pairs(np.arange(5.0), 1.0, "kitti")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="positive"):
        rpe_pairs(np.arange(5.0), 0.0)


def test_evaluation_records_and_uses_the_pairing():
    from coloradar.odometry import evaluate_trajectory
    from coloradar.odometry.evaluation import evaluation_dict

    ref = _wander()
    est = _noisy(ref)
    ev = evaluate_trajectory(est, ref, distances=(1.0,), rpe_pairing="evo")
    expected = _brute_evo_consecutive(est.translations, 1.0)
    assert ev.rpe[0].pairs == len(expected) and ev.rpe[0].pairing == "evo"
    assert evaluation_dict(ev)["info"]["rpe_pairing"] == "evo"
