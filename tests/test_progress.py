"""The progress printer: lines go through while a bar is open; a disabled printer is silent."""

from __future__ import annotations

import io

from cablesim.progress import Progress


def test_lines_print_while_a_bar_is_open():
    buf = io.StringIO()
    say = Progress("t", True, stream=buf)
    with say.bar(3, "work") as bar:
        say("first")
        bar.update(2)
    say("after")
    lines = buf.getvalue().splitlines()
    assert [line.split("] ", 1)[1] for line in lines] == ["first", "after"]


def test_a_disabled_printer_prints_nothing():
    buf = io.StringIO()
    say = Progress("t", False, stream=buf)
    with say.bar(2, "work") as bar:
        say("hidden")
        bar.update(1)
    assert buf.getvalue() == ""
