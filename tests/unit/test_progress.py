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
    update(0.55)      # the first steps: the rate counts from here
    update(0.65)
    bar = update.bar
    meter = bar.format_dict
    assert meter["initial"] == 0.55 and meter["n"] == 0.65
    # tqdm's rate is (n - initial) / elapsed: 0.1 m in 2 s, 0.35 m to go: 7 s, not 2 / 0.65 * 0.35
    assert bar.format_meter(**{**meter, "elapsed": 2.0}).endswith("<00:07]")
    update(None)


def test_the_rate_leaves_out_the_time_before_the_first_steps(capsys):
    """54 s of compilation before the first step once made 0.008 m braided read as an ETA of
    hours; the rate counts from the first steps, so 0.01 m in 2 s of braiding leaves 0.98 m for
    196 s."""
    update = progress_bar(1.0, True)
    update(0.0)
    bar = update.bar
    bar.start_t -= 54.0                  # the compilation during the first step
    update(0.01)
    assert bar._time() - bar.start_t < 5.0 and bar.initial == 0.01
    update(0.02)
    meter = bar.format_dict
    assert bar.format_meter(**{**meter, "elapsed": 2.0}).endswith("<03:16]")
    update(None)


def test_no_bar_when_disabled():
    update = progress_bar(1.0, False)
    update(0.5)
    update(None)
