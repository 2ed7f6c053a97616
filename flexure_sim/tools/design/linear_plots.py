"""
The figures and tables of ``flexure-sim modes | frf`` (tools/design/linear_commands.py).

Mode-shape PNGs, the Bode plot and the FRF's CSV, and how the linearisation point is written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


#: Coordinate names of rotations: the planar ``theta`` and the spatial ``rx``, ``ry``, ``rz``.
ROTATIONS = ("theta", "rx", "ry", "rz")


def input_text(mech, u0) -> str:
    """
    Where a model was linearised or a derivative taken: each drive's input with its unit.

    ``u0``: a number (one drive) or one value per drive; "rest (no drive)" without drives.
    """
    if not mech.drives:
        return "rest (no drive)"
    values = np.atleast_1d(np.asarray(u0, dtype=float))
    parts = []
    for d, v in zip(mech.drives, values):
        turn = d.coordinate in ROTATIONS
        if d.kind == "force":
            text = f"{v:.6g} {'N m' if turn else 'N'}"
        else:
            text = f"{v:.6g} rad" if turn else f"{v * 1e6:.6g} um"
        parts.append(text if len(values) == 1 else f"{d.name} {text}")
    return ("drive input " if len(values) == 1 else "drive inputs ") + ", ".join(parts)


def plot_modes(mech, model, md, count: int, out_dir: Path) -> list[Path]:
    """
    One PNG per mode.

    Bodies (lines from each body's centre to its hinge points) at rest in grey and displaced by the
    mode shape (scaled to 12 % of the mechanism's size).
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    z_rest = model.z
    size = max(float(np.ptp(z_rest.reshape(-1, 3)[:, :2])), 1e-3)
    points = {b.name: [] for b in mech.bodies}
    for h in mech.hinges:
        points[h.a.body].append(h.a.position)
        points[h.b.body].append(h.b.position)
    paths = []
    for k in range(min(count, len(md.frequencies))):
        dz = np.zeros_like(z_rest)
        dz[model.free] = md.shapes[:, k]
        pts = _mode_points(mech, points, z_rest, dz)
        span = max(np.max(np.abs(d - r)) for r, d in pts.values())
        scale = 0.12 * size / span if span > 0 else 1.0
        fig, ax = plt.subplots(figsize=(6, 5))
        for name, (rest, disp) in pts.items():
            moved = rest + scale * (disp - rest)
            for arr, style in ((rest, dict(color="0.7", lw=1.5)), (moved, dict(color="C0", lw=2))):
                for q in arr[1:]:
                    ax.plot([arr[0, 0] * 1e3, q[0] * 1e3], [arr[0, 1] * 1e3, q[1] * 1e3], **style)
            ax.plot(moved[1:, 0] * 1e3, moved[1:, 1] * 1e3, "o", color="C3", ms=5)
            ax.annotate(name, moved[0] * 1e3, fontsize=8, ha="center", va="bottom")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(
            f"{mech.name}: mode {k + 1}, {md.frequencies[k]:.6g} Hz\n"
            "grey: at rest; blue: displaced (scaled to be visible); red: hinges",
            fontsize=10,
        )
        path = out_dir / f"mode_{k + 1}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _mode_points(mech, points, z, dz):
    """
    Per body.

    (rest, displaced) arrays of [centre, hinge points...] in the root frame (the displacement to
    first order: d(P + R c) = dP + dtheta J R c).
    """
    out = {}
    for i, body in enumerate(mech.bodies):
        x, y, th = z[3 * i:3 * i + 3]
        c, s = np.cos(th), np.sin(th)
        rest = [np.array([x, y])] + [
            np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]]) for p in points[body.name]
        ]
        dx, dy, dth = dz[3 * i:3 * i + 3]
        disp = [q + np.array([dx, dy]) + dth * np.array([-(q[1] - y), q[0] - x]) for q in rest]
        out[body.name] = (np.array(rest), np.array(disp))
    return out


def unit(mech, model, name: str, source: str) -> str:
    """Return the unit of the FRF from input ``source`` to output ``name`` (SI)."""
    drive = mech.drives[model.input_index(source)]
    turn = drive.coordinate in ROTATIONS
    den = ("N m" if turn else "N") if drive.kind == "force" else ("rad" if turn else "m")
    outs = {o.name: o for o in mech.all_outputs}
    if name in outs:
        num = "rad" if outs[name].coordinate in ROTATIONS else "m"
    elif name == "compression" or name.startswith("drive_position"):
        num = "m"
    else:
        num = "N m" if ".moment" in name else "N"
    return f"{num}/{den}"


def write_frf_csv(f, G, outputs, path: Path) -> Path:
    cols = ["frequency_hz"]
    data = [f]
    for name, row in zip(outputs, G):
        cols += [f"{name}.magnitude", f"{name}.phase_deg", f"{name}.real", f"{name}.imag"]
        data += [np.abs(row), np.degrees(np.unwrap(np.angle(row))), row.real, row.imag]
    np.savetxt(
        path, np.column_stack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.10g"
    )
    return path


def plot_bode(mech, model, f, G, outputs, path: Path, source: str = "drive") -> Path:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    marker = "o" if len(f) <= 20 else None  # a few frequencies (or one) show as points
    for name, row in zip(outputs, G):
        unit_text = unit(mech, model, name, source)
        ax1.loglog(f, np.abs(row), label=f"{name} [{unit_text}]", marker=marker)
        ax2.semilogx(f, np.degrees(np.unwrap(np.angle(row))), label=name, marker=marker)
    ax1.set_ylabel("magnitude")
    ax2.set_ylabel("phase [deg]")
    ax2.set_xlabel("frequency [Hz]")
    ax1.legend(fontsize=8)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.grid(True, which="both", alpha=0.3)
    what = "drive" if len(model.input_names) == 1 else f"drive {source}"
    ax1.set_title(f"{mech.name}: {what} command -> outputs, linearised at\n"
                  f"{input_text(mech, model.u0)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
