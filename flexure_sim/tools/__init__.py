"""Command-line tools built on the engine and the recording layer (analysis, replay, fitting)."""
