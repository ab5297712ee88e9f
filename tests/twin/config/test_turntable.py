"""002's turntable file (twin.config.turntable): bad input is one line naming the key."""

from __future__ import annotations

import tomllib

import pytest

from tests.conftest import SCENARIO_DIR
from twin.config.scenario import ScenarioError
from twin.config.turntable import parse_turntable

FILE = SCENARIO_DIR / "seed002_turntable.toml"


def test_bad_file_is_one_line():
    data = tomllib.loads(FILE.read_text())
    data["unit"]["grade"] = "nope"
    with pytest.raises(ScenarioError, match="unit.grade"):
        parse_turntable(data, "x.toml")
