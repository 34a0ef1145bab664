"""One source of truth per tunable (issue 10): the options, the ROS parameter file and
the README table agree with ``grasp_apso/tunables.py``."""

import dataclasses
from pathlib import Path

import pytest

from grasp_apso import tunables
from grasp_apso.errors import InputError
from grasp_apso.search.options import PlanOptions
from grasp_apso.search.swarm import SwarmOptions

ROOT = Path(__file__).resolve().parents[1]


def test_config_file_is_generated_from_the_table():
    assert (ROOT / "config" / "grasp_apso.yaml").read_text() == tunables.yaml_text()


def test_readme_parameter_table_is_generated_from_the_table():
    readme = (ROOT / "README.md").read_text()
    assert tunables.markdown_table() in readme


@pytest.mark.parametrize("cls", [PlanOptions, SwarmOptions])
def test_option_defaults_come_from_the_table(cls):
    for f in dataclasses.fields(cls):
        try:
            spec = tunables.spec(f.name)
        except KeyError:
            continue
        assert f.default == spec.default, f.name


@pytest.mark.parametrize("name", [t.name for t in tunables.TUNABLES if t.lo is not None])
def test_ranges_are_enforced_with_the_field_named(name):
    spec = tunables.spec(name)
    below = spec.lo - (1 if spec.kind is int else 1e-6)
    if spec.lo_open:
        below = spec.lo
    with pytest.raises(InputError, match=rf"^{name}:"):
        spec.check(spec.kind(below))
    with pytest.raises(InputError, match=rf"^{name}:"):
        spec.check(spec.kind(spec.hi + (1 if spec.kind is int else 1e-6)))
    assert spec.check(spec.default) == spec.default


def test_plan_options_reject_a_bad_value_naming_it():
    with pytest.raises(InputError, match="^particles:"):
        PlanOptions(particles=1)
    with pytest.raises(InputError, match="^clearance:"):
        PlanOptions(clearance=-0.001)
    with pytest.raises(InputError, match="^algorithm:"):
        PlanOptions(algorithm="ga")
