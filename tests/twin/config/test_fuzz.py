"""Fuzz: every key of every shipped scenario file (face scenarios, 000's experiments, 002's turntable) made wrong
in type, NaN, inf, negative, zero or huge. Each case either loads and passes the resource estimate, or is refused
with one ScenarioError line naming the file: never a traceback, never a hang. In-process through the loader for
all of them; a sample through `longwall run` (rc 2, one line on stderr, nothing written in --out)."""

from __future__ import annotations

import pytest
import math
import subprocess
import sys
import tomllib

from tests.conftest import SCENARIO_DIR
from twin.config.resources import check_resources, estimate_resources
from twin.config.scenario import ScenarioError, parse_any, scenario_to_toml

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

FILES = ("default", "seed003_interference", "seed004_fault", "seed002_face", "seed000_alignment",
         "seed000_lever_arm", "seed000_coning", "seed000_sculling", "seed002_turntable")
"""Every kind of file, and faults, stops and canopy units among the face scenarios."""
MUTATIONS = {"type": "x", "nan": math.nan, "inf": math.inf, "negative": -1.0e3, "zero": 0, "huge": 1.0e300}


def leaves(node, path=()):
    """Paths of every scalar (and of the first element of every list of scalars) of a TOML tree."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for key, value in items:
        if isinstance(value, dict) or (isinstance(value, list) and value and isinstance(value[0], dict | list)):
            yield from leaves(value, (*path, key))
        else:
            yield (*path, key)
            if isinstance(value, list) and value:
                yield (*path, key, 0)


def mutated(data: dict, path: tuple, value):
    data = tomllib.loads(tomllib_dumps(data))  # a deep copy
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


def tomllib_dumps(data: dict) -> str:
    """TOML text of plain data (the project's writer, on a stand-in for a model)."""

    class Plain:
        def model_dump(self, exclude_none=True):
            return data

    return scenario_to_toml(Plain())


def cases():
    for name in FILES:
        data = tomllib.loads((SCENARIO_DIR / f"{name}.toml").read_text())
        for path in leaves(data):
            for label, value in MUTATIONS.items():
                yield f"{name}:{'.'.join(map(str, path))}:{label}", mutated(data, path, value)


def outcome(source: str, data: dict) -> str:
    """'loads' or the refusal's one line; anything else (a traceback) fails the test."""
    try:
        check_resources(source, estimate_resources(parse_any(data, source)))
    except ScenarioError as err:
        message = str(err)
        assert "\n" not in message and message.startswith(f"{source}: "), message
        return message
    return "loads"


def test_fuzz_in_process():
    results = {case: outcome(f"{case}.toml", data) for case, data in cases()}
    refused = [c for c, r in results.items() if r != "loads"]
    assert len(results) >= 1000 and len(refused) >= 150, (len(results), len(refused))
    for label in MUTATIONS:  # type, NaN, inf and huge break nearly every key; zero and negative many
        assert sum(c.endswith(f":{label}") for c in refused) >= 50, label
    assert all(results[c] != "loads" for c in results if c.split(":")[2] in ("type", "nan", "inf")
               and not c.split(":")[1].endswith(("name", "kind"))), "a non-number accepted"


def test_fuzz_through_the_command_line(tmp_path):
    """A sample of the refused cases through `longwall run` in parallel: rc 2, one line on stderr, no --out."""
    sample = [(c, d) for c, d in cases() if c.split(":")[2] in ("nan", "huge")][::151][:3]  # 3 s of imports each
    procs = []
    for k, (case, data) in enumerate(sample):
        path = tmp_path / f"case{k}.toml"
        path.write_text(tomllib_dumps(data))
        if outcome(str(path), tomllib.loads(path.read_text())) == "loads":
            continue
        procs.append((case, tmp_path / f"out{k}", subprocess.Popen(
            [sys.executable, "-m", "twin.cli", "run", str(path), "--out", str(tmp_path / f"out{k}"), "--quiet"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)))
    assert len(procs) == 3
    for case, out, proc in procs:
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 2 and err.count("\n") == 1 and err.startswith("longwall: error: "), (case, err)
        assert not out.exists(), case
