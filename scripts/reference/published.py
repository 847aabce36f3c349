"""A PEtab problem for the peers, from a folder of tests/data/petab or as published: the copies
in tests/data/petab leave out the visualization tables that petab's loader would read."""

from pathlib import Path

import petab.v1 as petab
import yaml


def load(folder: Path, name: str) -> petab.Problem:
    config = yaml.safe_load((folder / f"{name}.yaml").read_text())
    for entry in config["problems"]:
        entry.pop("visualization_files", None)
    return petab.Problem.from_yaml(config, base_path=str(folder))
