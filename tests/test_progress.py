"""Progress displays: a bar on a terminal, a line per stage in a log, nothing when quiet."""

import io

from tactile_manip.progress import StageLines, progress_bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_off_a_terminal_a_stage_is_one_line_with_its_count_and_time():
    log = io.StringIO()
    with progress_bar(total=300, desc="training contact x5", unit="epoch", stream=log) as bar:
        assert isinstance(bar, StageLines)
        for _ in range(300):
            bar.update()
        bar.set_postfix(val_rmse="0.41")
    lines = log.getvalue().splitlines()
    assert len(lines) == 1 and "\r" not in log.getvalue()
    assert lines[0].startswith("training contact x5: 300/300 epoch (val_rmse=0.41) in ") and lines[0].endswith(" s")


def test_a_long_stage_off_a_terminal_says_it_is_alive_at_most_once_per_heartbeat():
    log = io.StringIO()
    bar = progress_bar(total=3, desc="labelling", unit="pass", stream=log, heartbeat_s=0.0)
    bar.update()
    bar.update()
    bar.close()
    bar.close()  # closing twice writes nothing more
    lines = log.getvalue().splitlines()
    assert len(lines) == 3
    assert lines[0].startswith("labelling: 1/3 pass, ") and lines[0].endswith(" s so far")
    assert lines[1].startswith("labelling: 2/3 pass, ") and lines[2].startswith("labelling: 2/3 pass in ")
    quiet_log = io.StringIO()
    bar = progress_bar(total=3, desc="labelling", stream=quiet_log, heartbeat_s=3600.0)
    bar.update()
    assert quiet_log.getvalue() == ""  # within the heartbeat: nothing until the stage ends


def test_quiet_prints_nothing_even_on_a_terminal():
    term = _Terminal()
    with progress_bar(total=5, desc="simulating", quiet=True, stream=term) as bar:
        bar.update(5)
    assert term.getvalue() == ""


def test_on_a_terminal_it_is_a_bar():
    term = _Terminal()
    with progress_bar(total=2, desc="simulating", unit="pair", stream=term) as bar:
        assert not isinstance(bar, StageLines)
        bar.update(2)
    assert "simulating" in term.getvalue()


def test_a_closed_log_does_not_end_the_work():
    log = io.StringIO()
    bar = progress_bar(total=2, desc="x", stream=log, heartbeat_s=0.0)
    log.close()
    bar.update()
    bar.close()  # no ValueError from the closed stream
