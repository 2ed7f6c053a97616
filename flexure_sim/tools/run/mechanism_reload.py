"""
The mechanism a recorded run simulated.

Reloaded from the run's ``flexure_sim`` metadata record, and what it adds to the recorded poses
(hinge frame displacements, Figure 6.4).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from flexure_sim.tools.run.series import Series


def load_recorded_mechanism(meta: dict[str, str]) -> tuple[Any, str]:
    """
    (mechanism, '') or (None, why not).

    Tried in order: the YAML text stored in the metadata (what actually ran), the file at the
    recorded path, the built-in of the recorded name. A run of the spatial engine (``space``
    ``3d`` in the metadata) is loaded as a spatial mechanism (a planar file opened in 3-D).
    """
    from flexure_sim.engine.mechanism.loader import (
        ConfigError, load_mechanism, mechanism_from_dict,
    )
    from flexure_sim.engine.mechanism.spatial_loader import load_spatial, spatial_from_dict

    spatial = meta.get("space") == "3d"
    from_dict = spatial_from_dict if spatial else mechanism_from_dict
    load = load_spatial if spatial else load_mechanism
    problems = []
    path = meta.get("mechanism_path", "")
    name = meta.get("mechanism_name") or meta.get("mechanism") or ""
    text = meta.get("mechanism_yaml", "")
    if not (text or path or name):
        return None, "the file has no flexure_sim metadata record naming the mechanism"
    if text:
        try:
            import yaml

            return from_dict(yaml.safe_load(text), source=path or "<recorded YAML>"), ""
        except ConfigError as exc:
            problems.append(f"recorded YAML: {exc}")
        except Exception as exc:  # noqa: BLE001 - yaml.YAMLError and whatever bad text raises
            problems.append(f"recorded YAML: {type(exc).__name__}: {exc}")
    for candidate in (path, name):
        if not candidate:
            continue
        try:
            return load(candidate), ""
        except (ConfigError, OSError, ValueError) as exc:
            problems.append(str(exc))
    return None, "; ".join(problems)


def hinge_frame_displacements(
    mech: Any, hinge: str, poses: dict[str, Series]
) -> Optional[tuple[np.ndarray, np.ndarray, np.ndarray, str, str]]:
    """
    Displacement from rest (root frame, m) of a hinge's frame on body A and on body B.

    It is computed from the recorded body poses and the mechanism's frame positions.

    Returns (t, disp_a (n, 2), disp_b (n, 2), body A, body B), or None when the hinge or the
    poses of its two bodies (sampled at the same times) are not available.
    """
    from flexure_sim.engine.mechanism.loader import frame_pose_at_rest

    try:
        h = mech.hinges[mech.hinge_index(hinge)]
        body_a = mech.bodies[mech.body_index(h.a.body)]
        body_b = mech.bodies[mech.body_index(h.b.body)]
    except ValueError:
        return None
    if h.a.body not in poses or h.b.body not in poses:
        return None
    pa, pb = poses[h.a.body], poses[h.b.body]
    if pa.t.shape != pb.t.shape or not np.array_equal(pa.t, pb.t):
        return None

    def displacement(frame: Any, body: Any, series: Series) -> np.ndarray:
        rest = frame_pose_at_rest(frame, body)[0]
        return np.array([frame_pose_at_rest(frame, replace(body, pose=tuple(p)))[0] - rest
                         for p in series.values.tolist()]).reshape(len(series), 2)

    return pa.t, displacement(h.a, body_a, pa), displacement(h.b, body_b, pb), h.a.body, h.b.body
