"""baselines/cli.flags: the command a run or an evaluation configured in code writes down."""

from dataclasses import asdict, dataclass
from typing import Optional

import tyro

from baselines import cli


@dataclass
class Example:
    seed: int = 1
    sample: bool = True
    stages: tuple[str, ...] = ("cp1", "cp2")
    out: Optional[str] = None


def test_flags_name_what_differs_and_parse_back():
    configured = Example(seed=1, sample=False, stages=("cp4",), out="runs/x")
    flags = cli.flags(asdict(configured), asdict(Example()))
    # the seed equals its default and is left out; a False bool is its --no- flag; a tuple's values follow one flag
    assert flags == ["--no-sample", "--stages", "cp4", "--out", "runs/x"]
    assert tyro.cli(Example, args=flags) == configured


def test_flags_always_names_the_fields_asked_for():
    flags = cli.flags(asdict(Example()), asdict(Example()), always=("seed",))
    assert flags == ["--seed", "1"]
    assert cli.flags(asdict(Example()), asdict(Example())) == []
