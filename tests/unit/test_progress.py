"""The progress line: compiling said as such, the ETA of a resumed run from what it braids since."""

from __future__ import annotations

from preform.stepping import STARTING, progress_bar


def test_the_first_line_says_the_kernels_compile_then_braiding(capsys):
    update = progress_bar(1.0, True)
    update(0.0)
    assert update.bar.desc == STARTING
    update(0.1)
    assert update.bar.desc == "braiding"
    update(None)


def test_a_resumed_run_estimates_its_time_from_the_length_braided_since(capsys):
    update = progress_bar(1.0, True, start=0.5)
    update(0.5)
    update(0.6)
    bar = update.bar
    meter = bar.format_dict
    assert meter["initial"] == 0.5 and meter["n"] == 0.6
    # tqdm's rate is (n - initial) / elapsed: 0.1 m in 2 s, 0.4 m to go: 8 s, not 2 / 0.6 * 0.4
    assert bar.format_meter(**{**meter, "elapsed": 2.0}).endswith("<00:08]")
    update(None)


def test_no_bar_when_disabled():
    update = progress_bar(1.0, False)
    update(0.5)
    update(None)
