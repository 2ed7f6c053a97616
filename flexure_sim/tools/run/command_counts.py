"""
What became of a run's drive commands: the node's command counters and its rejected payloads.

The stage node counts every drive command it takes (node/inputs/command_checks.py,
``CommandCounters``) and publishes the running totals in its diagnostics status
(node/publish/diagnostics.py) as ``commands_<counter>`` (one drive) or
``commands_<drive>_<counter>`` (several): ``received``; ``accepted`` (finite, clamped ones
included: the commands applied); ``clamped`` (outside the stroke, applied at its end);
``rejected`` (not finite, or malformed); ``malformed`` (not a Float64); ``rate_limited``;
``lost`` (sent, replaced in the reader before a tick took them); ``unheard`` (sent before the
reader matched the publisher). A malformed payload is recorded on the command topic's
``<topic>/rejected`` channel (node/inputs/command_intake.py).

`load_run` keeps the last diagnostics status with counters (the totals of the whole run)
and the number of messages on each rejected channel (``Run.tallies``); `command_counts` and
`format_command_counts` turn them into the line ``flexure-sim analyse`` prints.
"""
from __future__ import annotations

from typing import Any, Optional

from flexure_sim.topics import DIAGNOSTICS

DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
#: Suffix of a command topic's channel of malformed payloads (`command_intake.REJECTED_SUFFIX`).
REJECTED_SUFFIX = "/rejected"
#: The node's command counters, in the order they are reported.
COUNTERS = ("received", "accepted", "clamped", "rejected", "malformed", "rate_limited", "lost",
            "unheard")
_PREFIX = "commands_"


def tallied(name: str, type_name: str, namespace: Optional[str]) -> bool:
    """Whether topic ``name`` is the stage's diagnostics or one of its rejected channels."""
    if namespace is not None and not name.startswith(namespace + "/"):
        return False
    if type_name == DIAGNOSTICS_TYPE:
        return name.endswith("/" + DIAGNOSTICS)
    return name.endswith(REJECTED_SUFFIX)


def tally(previous: Any, message: Any) -> Any:
    """Fold one message into a channel's tally: a count, or the last diagnostics values."""
    if hasattr(message, "status"):
        values = {kv.key: kv.value for st in message.status for kv in st.values}
        return values if any(k.startswith(_PREFIX) for k in values) else previous
    return previous + 1


def split_tallies(tallies: dict[str, Any], namespace: str) -> tuple[dict[str, str],
                                                                    dict[str, int]]:
    """Return (last diagnostics values of the stage in ``namespace``, rejected channel counts)."""
    prefix = namespace + "/"
    diagnostics = tallies.get(prefix + DIAGNOSTICS) or {}
    rejected = {name: n for name, n in tallies.items()
                if name.endswith(REJECTED_SUFFIX) and name.startswith(prefix)
                and isinstance(n, int)}
    return (diagnostics if isinstance(diagnostics, dict) else {}), rejected


def command_counts(run: Any, drives: Optional[list[str]] = None) -> Optional[dict]:
    """
    Return the run's command counts, or None when it recorded no diagnostics with counters.

    ``{"drives": {name or "": {counter: n}}, "rejected_messages": {topic: n}}``: per drive
    (``drives``: the run's drive names; one entry "" for a single drive's ``commands_<counter>``)
    the counters its last diagnostics status holds, and the messages per rejected channel.
    """
    values, rejected = split_tallies(run.tallies, run.namespace)
    per: dict[str, dict[str, int]] = {}
    for name in (drives or [""]):
        head = _PREFIX + (f"{name}_" if name else "")
        found = {c: _int(values.get(head + c)) for c in COUNTERS}
        found = {c: v for c, v in found.items() if v is not None}
        if found:
            per[name] = found
    if not per and drives:
        return command_counts(run)
    if not per:
        return None
    return {"drives": per, "rejected_messages": dict(sorted(rejected.items()))}


def _int(text: Optional[str]) -> Optional[int]:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def format_command_counts(counts: Optional[dict]) -> str:
    """One line: the counts of every drive and the messages on the rejected channels."""
    if counts is None:
        return "commands: no counts (the run has no diagnostics of the stage node)"
    parts = []
    for name, found in counts["drives"].items():
        text = ", ".join(f"{n} {c.replace('_', '-')}" for c, n in found.items())
        parts.append(f"drive {name}: {text}" if name else text)
    rejected = sum(counts["rejected_messages"].values())
    return (f"commands (node's counters at the end of the run): {'; '.join(parts)}; "
            f"{rejected} message(s) on the rejected channels")
