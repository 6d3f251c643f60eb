"""Progress bars turn themselves off when their stream is not a terminal."""

from __future__ import annotations

import io

from semattnet._utils.progress import is_interactive, progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_no_refresh_lines_on_a_non_tty_stream() -> None:
    log = io.StringIO()
    assert not is_interactive(log)
    assert sum(progress(range(50), file=log, desc="epoch 0", mininterval=0)) == sum(range(50))
    assert log.getvalue() == ""  # no bar, no carriage-return refreshes
    with progress(total=3, file=log) as bar:
        bar.update(3)
    assert log.getvalue() == ""


def test_bar_on_a_terminal_or_when_forced() -> None:
    tty = _Tty()
    list(progress(range(5), file=tty, desc="epoch 0", mininterval=0))
    assert "\r" in tty.getvalue() and "5/5" in tty.getvalue()
    forced = io.StringIO()
    list(progress(range(5), file=forced, force=True, mininterval=0))
    assert "5/5" in forced.getvalue()
    hidden = _Tty()
    list(progress(range(5), file=hidden, enabled=False))
    assert hidden.getvalue() == ""
