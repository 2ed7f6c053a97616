"""
Steps of several drives and the gain matrix they measure: pure functions on NumPy arrays.

Definitions (``flexure-sim analyse`` of a run with several drives or outputs; docs/tools.md):

- The steps of each drive are found as for one drive (`analysis.command_steps` on its
  command, else `analysis.input_steps` on its applied input). The steps of all drives are
  taken together in time order; a step's **window** runs from its onset to the next onset of
  *any* drive (or the end of the run). Steps of two drives at the same time are reported
  but measure no gain (the change cannot be told apart).
- A step is **clean** when the other drives **hold**: the applied input of each other drive
  changes over the window by no more than `HOLD_TOLERANCE` of the range it covers in the run.
- Per (step, output): the output's settled values before and after (`analysis` definitions),
  its change, settling time, overshoot and rise time (`response_metrics.step_response`), and
  the **gain** output change / applied input change of the stepped drive. An output whose
  change is below `NO_RESPONSE` of the largest change it shows in the run (an uncoupled
  pair) is settled when its input is, with no settling time or overshoot.
- The **gain matrix** entry (output o, drive d) is the least-squares slope through the
  (input change, output change) pairs of the clean, settled steps of drive d:
  sum(du dy) / sum(du^2) (the step's gain when there is one step); None without such a step.
  Settling time and overshoot of the pair are the largest over those steps.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from flexure_sim.tools.run.step_analysis import Signal, Step, _before, _window
from flexure_sim.tools.run.response_metrics import DEFAULT_BAND, DEFAULT_HOLD, step_response

#: A drive holds during another's step if its input moves by at most this fraction of its range.
HOLD_TOLERANCE = 1e-6
#: An output changing by less than this fraction of its largest change in the run: no response.
NO_RESPONSE = 1e-6


@dataclass
class OutputResponse:
    """One output's response to one step (units of the output; times in s from the onset)."""

    before: Optional[float] = None
    after: Optional[float] = None
    change: Optional[float] = None
    gain: Optional[float] = None
    settling_time: Optional[float] = None
    overshoot: Optional[float] = None
    rise_time: Optional[float] = None
    settled: bool = False
    #: Set by the caller: the same ratio from a static solve at the same inputs.
    static_gain: Optional[float] = None


@dataclass
class DriveStep:
    """One step of one drive and the response of every output to it."""

    index: int
    drive: str
    t: float
    input_before: float
    input: float
    duration: float
    applied_input_before: Optional[float] = None
    applied_input: Optional[float] = None
    input_change: Optional[float] = None
    input_settled: bool = False
    clean: bool = True
    outputs: dict[str, OutputResponse] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "outputs"}
        d["notes"] = list(self.notes)
        d["outputs"] = {k: dict(v.__dict__) for k, v in self.outputs.items()}
        return d


def _span(sig: Signal) -> float:
    return float(np.max(sig[1]) - np.min(sig[1])) if sig[0].shape[0] else 0.0


def _output_changes(steps: Sequence[tuple[str, Step]], ends: Sequence[float],
                    sig: Signal) -> float:
    """Largest |change| of an output between step onsets and window ends (its scale)."""
    largest = 0.0
    for (_, s), t1 in zip(steps, ends):
        y0, w = _before(sig, s.t), _window(sig, s.t, t1)
        if y0 is not None and w[0].shape[0]:
            largest = max(largest, abs(float(w[1][-1]) - y0))
    return largest


def analyse_drive_steps(
    steps: dict[str, Sequence[Step]],
    inputs: dict[str, Signal],
    outputs: dict[str, Signal],
    t_end: float,
    band: float = DEFAULT_BAND,
    hold: float = DEFAULT_HOLD,
) -> list[DriveStep]:
    """
    Every step of every drive, in time order, with the response of every output.

    ``steps``: per drive, its steps; ``inputs``: per drive, its applied input (t, values);
    ``outputs``: per output, (t, values); ``t_end``: end of the run (s).
    """
    merged = sorted(((d, s) for d, ss in steps.items() for s in ss), key=lambda x: x[1].t)
    onsets = sorted({s.t for _, s in merged})
    ends = []
    for _, s in merged:
        later = [t for t in onsets if t > s.t]
        ends.append(later[0] if later else max(t_end, s.t))
    spans = {d: _span(sig) for d, sig in inputs.items()}
    scales = {o: _output_changes(merged, ends, sig) for o, sig in outputs.items()}
    out: list[DriveStep] = []
    for i, ((drive, s), t1) in enumerate(zip(merged, ends)):
        st = DriveStep(i + 1, drive, s.t, s.previous, s.target, t1 - s.t)
        out.append(st)
        together = sorted({d for d, o in merged if o.t == s.t and d != drive})
        if together:
            st.clean = False
            st.notes.append(f"drive(s) {', '.join(together)} stepped at the same time: no gain")
        for other, sig in inputs.items():
            if other == drive or other in together:
                continue
            u0, w = _before(sig, s.t), _window(sig, s.t, t1)
            if u0 is not None and w[0].shape[0] and (
                    float(np.max(np.abs(w[1] - u0))) > HOLD_TOLERANCE * spans[other]):
                st.clean = False
                st.notes.append(f"drive {other} did not hold during the step: no gain")
        du = s.target - s.previous
        sig = inputs.get(drive)
        if sig is not None and sig[0].shape[0]:
            u0, (ut, uy) = _before(sig, s.t), _window(sig, s.t, t1)
            if u0 is not None and ut.shape[0]:
                r = step_response(ut, uy, s.t, u0, t1, band, hold)
                st.applied_input_before, st.applied_input = u0, r.final
                st.input_settled, du = r.settled, r.change
                if not r.settled:
                    st.notes.append("the drive input did not settle before the next step")
            else:
                st.notes.append("no applied input around the step")
        st.input_change = du
        for name, sig in outputs.items():
            st.outputs[name] = _response(sig, s.t, t1, du, st.input_settled, scales[name],
                                         band, hold)
            if not st.outputs[name].settled and st.outputs[name].change is not None:
                st.notes.append(f"output {name} did not settle before the next step")
        if du == 0.0:
            st.notes.append("the applied input did not change (clamped to the stroke?)")
    return out


def _response(sig: Signal, t0: float, t1: float, du: float, input_settled: bool,
              scale: float, band: float, hold: float) -> OutputResponse:
    y0, (wt, wy) = _before(sig, t0), _window(sig, t0, t1)
    r = OutputResponse()
    if y0 is None or wt.shape[0] == 0:
        return r
    change = float(wy[-1]) - y0
    r.before, r.after, r.change = y0, float(wy[-1]), change
    if abs(change) <= NO_RESPONSE * scale:
        r.settled = input_settled
    else:
        m = step_response(wt, wy, t0, y0, t1, band, hold)
        r.settling_time, r.overshoot, r.rise_time = m.settling_time, m.overshoot, m.rise_time
        r.settled = m.settled and input_settled
    if r.settled and du != 0.0:
        r.gain = change / du
    return r


@dataclass(frozen=True)
class Pair:
    """The gain of one output against one drive, with its worst settling and overshoot."""

    drive: str
    output: str
    gain: Optional[float]
    steps: int
    settling_time: Optional[float]
    overshoot: Optional[float]


def gain_pairs(steps: Sequence[DriveStep], drives: Sequence[str],
               outputs: Sequence[str]) -> list[Pair]:
    """Each (drive, output) pair: least-squares gain over its clean settled steps (doc above)."""
    out = []
    for d in drives:
        for o in outputs:
            used = [s for s in steps if s.drive == d and s.clean and s.outputs[o].gain is not None]
            du = np.array([s.input_change for s in used], dtype=float)
            dy = np.array([s.outputs[o].change for s in used], dtype=float)
            gain = float(du @ dy / (du @ du)) if used else None
            ts = [s.outputs[o].settling_time for s in used
                  if s.outputs[o].settling_time is not None]
            ov = [s.outputs[o].overshoot for s in used if s.outputs[o].overshoot is not None]
            out.append(Pair(d, o, gain, len(used), max(ts) if ts else None,
                            max(ov) if ov else None))
    return out


def matrix(pairs: Sequence[Pair], drives: Sequence[str], outputs: Sequence[str],
           what: str = "gain") -> list[list[Optional[float]]]:
    """Rows per output, columns per drive, of one field of `Pair` (None where unknown)."""
    by = {(p.output, p.drive): getattr(p, what) for p in pairs}
    return [[by.get((o, d)) for d in drives] for o in outputs]
