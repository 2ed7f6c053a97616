"""
What every console script shares: a closed output pipe ends the command quietly.

``flexure-sim modes xy_stage | head -1``: ``head`` exits after one line, and the command's next
write to the pipe fails. A Unix tool is stopped by SIGPIPE there without a word, and its shell
reports status 141 (128 + SIGPIPE). Python ignores SIGPIPE, so the write raises
``BrokenPipeError`` instead, which a command's own ``except OSError`` reported as an error, or
the interpreter's last flush as "Exception ignored ... BrokenPipeError".

``quiet_pipe`` wraps a console script's ``main``: while it runs, a write to a closed stdout or
stderr raises ``PipeClosed``, a ``BaseException`` that no ``except Exception`` or
``except OSError`` of the command catches; the wrapper then returns ``PIPE_CLOSED`` (141)
without a message, having pointed the closed descriptor at /dev/null so nothing later fails.
SIGPIPE is not restored to its default action: the node's sockets and its recorder's pipe
must never kill the process.
"""
from __future__ import annotations

import functools
import os
import sys
from typing import Any, Callable, Optional, TypeVar

#: Exit status of a command whose output pipe was closed: a shell's for a tool stopped by SIGPIPE.
PIPE_CLOSED = 128 + 13

F = TypeVar("F", bound=Callable[..., Optional[int]])


class PipeClosed(BaseException):
    """The reader of stdout or stderr has gone (a closed pipe): the command stops quietly."""


class _Guarded:
    """A text stream whose writes raise ``PipeClosed`` when its pipe is closed."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def _closed(self) -> None:
        try:
            fd = self._stream.fileno()
        except (AttributeError, OSError, ValueError):
            fd = None
        if fd is not None:  # what is still buffered, and the interpreter's last flush, go nowhere
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, fd)
            os.close(null)
        raise PipeClosed

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._closed()
            raise  # not reached: _closed raises

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def quiet_pipe(main: F) -> F:
    """Wrap a console script's ``main``: a closed stdout or stderr ends it with PIPE_CLOSED."""
    @functools.wraps(main)
    def run(*args: Any, **kwargs: Any) -> Optional[int]:
        saved = sys.stdout, sys.stderr
        if sys.stdout is not None:
            sys.stdout = _Guarded(sys.stdout)
        if sys.stderr is not None:
            sys.stderr = _Guarded(sys.stderr)
        try:
            try:
                return main(*args, **kwargs)
            finally:  # flush what is buffered while a closed pipe can still be caught
                for stream in (sys.stdout, sys.stderr):
                    if stream is not None:
                        stream.flush()
        except PipeClosed:
            return PIPE_CLOSED
        finally:
            sys.stdout, sys.stderr = saved

    return run  # type: ignore[return-value]
