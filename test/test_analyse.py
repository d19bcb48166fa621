"""``uav_fusion analyse``: each analysis end to end on one short benchmark flight (single- and
multi-UAV), the accounting against the benchmark's own scores, the locked seconds, and the
errors that name the flag or file."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.analysis.locks import FrameFollow, profile_locks
from uav_fusion.core.bench.cache import cached_flights
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.multi import MultiScoreTask, multi_score_task
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

SITE_FILE = config_path(DEFAULT_SITE)


def _definition(tmp: Path, doc: dict[str, object]) -> Path:
    p = tmp / f"{doc['name']}.yaml"
    p.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def single(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("single")
    doc = {"name": "tiny", "plans": ["zigzag_dash"], "splits": {"tune": [3], "test": [4]},
           "duration_s": 90.0}  # fmt: skip
    return _definition(tmp, doc), tmp / "cache"


@pytest.fixture(scope="module")
def multi(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("multi")
    doc = {"name": "tiny_multi", "targets": "multi", "plans": ["multi_crossing_pair"],
           "splits": {"tune": [3], "test": [4]}, "duration_s": 200.0}  # fmt: skip
    return _definition(tmp, doc), tmp / "cache"


def _analyse(
    capsys: pytest.CaptureFixture[str], what: str, d: Path, cache: Path, *extra: str
) -> tuple[list[str], str]:
    argv = ["analyse", what, "--definition", str(d), "--cache", str(cache), "--split", "tune"]
    assert main([*argv, *extra]) == 0
    out, err = capsys.readouterr()
    return out.splitlines(), err


def _total(text: str) -> int:
    """The sum of the counts of a "cause n, cause n, ..." list (causes may hold commas)."""
    return sum(int(n) for n in re.findall(r" (\d+)(?:,|$)", text))


def test_single_uav_misses_account_for_every_missed_epoch_the_benchmark_counts(
    single: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    d, cache = single
    lines, err = _analyse(capsys, "misses", d, cache)
    # progress on stderr: the flight generated into the empty cache, then worked on
    assert "analyse misses: [1/1] zigzag_dash-s3: generating into" in err
    assert "analyse misses: [1/1] zigzag_dash-s3 (" in err
    m = re.fullmatch(r"\[1/1\] zigzag_dash-s3: (\d+) observable(.*)", lines[0])
    assert m is not None, lines[0]
    n_obs = int(m.group(1))
    unc = re.search(r"uncovered ([^;]*)", m.group(2))
    gross = re.search(r"gross ([^;]*)", m.group(2))
    n_unc = _total(unc.group(1)) if unc else 0
    n_gross = _total(gross.group(1)) if gross else 0
    # the benchmark's own score of the same run
    definition = load_definition(d)
    cf = cached_flights(definition, "tune", cache, SITE_FILE)[0]
    task = ScoreTask(cf, load_profile("tracker"), load_site(), definition.grid_hz,
                     definition.settings)  # fmt: skip
    s = score_task(task).samples
    assert n_obs == s.observable > 100
    assert n_unc == s.observable - s.observable_covered
    assert n_gross == s.observable_gross
    assert lines[1:3] == ["", f"tracker, tiny tune: {n_obs} radar-observable epochs"]
    assert lines[3].startswith(f"  nothing published: {n_unc} (")
    assert any(x.startswith(f"  more than 100 m off: {n_gross} (") for x in lines[4:])


def test_single_uav_oracle_and_locks_run(
    single: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    d, cache = single
    lines, _ = _analyse(capsys, "oracle", d, cache, "--gross-pct", "2")
    assert lines[0].startswith("[1/1] zigzag_dash-s3: observable coverage / gross %: tracker ")
    assert lines[2].split() == ["mean", "m", "p95", "m", "obs", "cov", "%", "obs", "gross", "%",
                                "cov", ">=", "99", "gross", "<=", "2", "both"]  # fmt: skip
    assert lines[3].startswith("tracker ") and lines[4].startswith("oracle ")
    assert lines[5].startswith("oracle gross epochs where the UAV's own radar reports of the")
    lines, _ = _analyse(capsys, "locks", d, cache, "--profiles", "tracker", "tracker_smoothed")
    assert lines[0].startswith("[1/1] zigzag_dash-s3: ")
    assert lines[2] == "pooled over 1 flights (seconds of confirmed track by what it follows):"
    for name, line in zip(("tracker", "tracker_smoothed"), lines[3:5], strict=True):
        m = re.fullmatch(rf"  {name}: (.*) \(of ([\d.]+) s\); more than 100 m off the UAV "
                         r"while on another object: ([\d.]+) s", line)  # fmt: skip
        assert m is not None, line
        assert 30.0 < float(m.group(2)) <= 90.0  # confirmed-track seconds of a 90 s flight
        assert "uav " in m.group(1)


def test_multi_uav_misses_oracle_and_false_tracks(
    multi: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    d, cache = multi
    lines, _ = _analyse(capsys, "misses", d, cache)
    m = re.fullmatch(r"\[1/1\] multi_crossing_pair-s3: missed UAV-epochs: (.*)", lines[0])
    assert m is not None, lines[0]
    missed = 0 if m.group(1) == "none" else _total(m.group(1))
    definition = load_definition(d)
    st = definition.settings
    cf = cached_flights(definition, "tune", cache, SITE_FILE)[0]
    task = MultiScoreTask(cf, load_profile("tracker"), load_site(), definition.grid_hz,
                          st.airborne_min_m, st.observable_window_s)  # fmt: skip
    uavs = multi_score_task(task).samples.uavs
    epochs = sum(u.epochs for u in uavs)
    assert missed == sum(u.epochs - int(np.sum(u.covered())) for u in uavs)
    pct = 100.0 * missed / epochs
    assert lines[2] == f"all UAVs, 1 flights: {missed} of {epochs} airborne UAV-epochs missed " \
        f"({pct:.2f} %)"  # fmt: skip
    assert any(x.startswith("silent UAVs: ") for x in lines)

    lines, _ = _analyse(capsys, "oracle", d, cache)
    m = re.fullmatch(r"\[1/1\] multi_crossing_pair-s3: GOSPA tracker ([\d.]+) m, "
                     r"oracle ([\d.]+) m", lines[0])  # fmt: skip
    assert m is not None, lines[0]
    table = "\n".join(lines[1:])
    assert "| tracker |" in table and "| oracle |" in table

    lines, _ = _analyse(capsys, "false-tracks", d, cache, "--strict-grounded")
    assert lines[0].startswith("[1/1] multi_crossing_pair-s3: false track-epochs: ")
    assert re.fullmatch(r"pooled over 1 flights: \d+ false track-epochs", lines[2])
    assert "excused" not in lines[3]
    assert lines[-1].startswith("confirmed tracks born on: ")


def test_locked_seconds_run_from_frame_to_frame() -> None:
    kinds = {
        1: (np.array([0.0]), [("uav", 1)]),
        2: (np.array([0.0]), [("bird", 9)]),
    }
    tt = np.array([0.0, 100.0])
    enu = np.zeros((2, 3))
    near, far = np.array([10.0, 0, 0, 0, 0, 0]), np.array([300.0, 0, 0, 0, 0, 0])
    frames = [
        FrameFollow(0.0, None, None),  # no confirmed track: 0-1 s not counted
        FrameFollow(1.0, 1, far),  # on the UAV (never a lock, however far): 1-3 s
        FrameFollow(3.0, 2, near),  # on a bird, near the UAV: 3-4 s
        FrameFollow(4.0, 2, far),  # on a bird, 300 m off: 4-6.5 s locked
        FrameFollow(6.5, 7, far),  # a track the twin does not know: as without radar
        FrameFollow(7.0, None, None),
        FrameFollow(8.0, 1, near),  # the last frame: nothing after it
    ]
    pl = profile_locks(iter(frames), kinds, tt, enu)
    assert pl.seconds == {"uav": 2.0, "bird": 3.5, "RF fixes only": 0.5}
    assert pl.locked_s == 3.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["locks", "--definition", "multi"], "--definition multi: analyse locks needs a "
         "single-UAV definition"),
        (["false-tracks", "--definition", "accuracy"], "--definition accuracy: analyse "
         "false-tracks needs a multi-UAV definition"),
        (["misses", "--definition", "multi", "--reentry-s", "3"], "--reentry-s applies to "
         "single-UAV definitions; --definition multi is a multi-UAV one"),
        (["oracle", "--window-s", "3", "--definition", "multi"], "--window-s applies to "
         "single-UAV definitions"),
        (["oracle", "--profile", "paper"], "--profile paper: analyse oracle needs a tracker "
         "profile"),
        (["locks", "--profiles", "tracker", "tracker"], "--profiles tracker: profile name "
         "'tracker' is used by two"),
        (["misses", "--definition", "no_such_definition"], "no_such_definition.yaml: "
         "benchmark definition not found"),
        (["misses", "--profile", "no_such_profile"], "no_such_profile.yaml: profile file not "
         "found"),
    ],
)  # fmt: skip
def test_bad_input_names_the_flag_or_file(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["analyse", *argv, "--cache", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("uav_fusion analyse: error: ") and message in err, err
    assert not any(tmp_path.iterdir())  # nothing generated
