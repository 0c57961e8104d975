"""`map --calibration`: the trajectory's run's calibration.csv named explicitly (reproduce's
plan names it, so that --ship-files sends it with the map's task) gives the same
calibration.yaml as the default, the calibration.csv beside the trajectory; a named file
that is not there is an input error naming it, with nothing written."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.maps import stage as map_stage
from fuzzyslam.slam import calibration_files
from fuzzyslam.slam import stage as run_stage

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"


@pytest.fixture(scope="module")
def sample_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sample") / "run"
    run_stage.run(SAMPLE, out)  # sample.yaml extends paper.yaml: slam.calibrate on
    return out


@pytest.mark.slow
def test_named_calibration_equals_the_one_beside_the_trajectory(sample_run, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(sample_run / "trajectory.tum", elsewhere / "trajectory.tum")
    shutil.copy(sample_run / "calibration.csv", tmp_path / "calib.csv")
    beside = map_stage.run(SAMPLE, sample_run / "trajectory.tum", tmp_path / "a",
                           until_run=1, figures=False)  # fmt: skip
    named = map_stage.run(SAMPLE, elsewhere / "trajectory.tum", tmp_path / "b", until_run=1,
                          figures=False, calibration=tmp_path / "calib.csv")  # fmt: skip
    # without the option, a trajectory with no calibration.csv beside it: no calibration
    none = map_stage.run(SAMPLE, elsewhere / "trajectory.tum", tmp_path / "c", until_run=1,
                         figures=False)  # fmt: skip
    a = yaml.safe_load((tmp_path / "a" / "calibration.yaml").read_text())
    b = yaml.safe_load((tmp_path / "b" / "calibration.yaml").read_text())
    assert a == b and beside["calibration"] == named["calibration"]
    t_end = beside["freeze_time"]
    want = calibration_files.at_time(sample_run / "calibration.csv", t_end)
    assert want is not None and a["factors"] == pytest.approx(want["factors"], rel=0, abs=0)
    assert "calibration" not in none and not (tmp_path / "c" / "calibration.yaml").exists()


def test_named_calibration_that_is_missing_is_an_input_error(sample_run, tmp_path):
    missing = tmp_path / "no" / "calibration.csv"
    with pytest.raises(InputError, match="no such calibration file") as exc:
        map_stage.run(SAMPLE, sample_run / "trajectory.tum", tmp_path / "m", until_run=1,
                      figures=False, calibration=missing)  # fmt: skip
    assert str(missing) in str(exc.value)
    assert not (tmp_path / "m").exists()
