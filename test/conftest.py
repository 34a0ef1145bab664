"""Shared pytest set-up for grasp_apso.

The tests exercise the working tree, not the copy of grasp_apso that `pip install .`
put into .venv: the repository root goes first on sys.path (pytest.ini does the same
with `pythonpath = .`), and first on PYTHONPATH so that subprocesses started by tests
(python -m grasp_apso...., the node) import the working tree too.
Shared fixtures are added below by the module owners.
"""
import os
import sys

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

if sys.path[:1] != [REPO_ROOT]:
    while REPO_ROOT in sys.path:
        sys.path.remove(REPO_ROOT)
    sys.path.insert(0, REPO_ROOT)

_pp = [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p and p != REPO_ROOT]
os.environ['PYTHONPATH'] = os.pathsep.join([REPO_ROOT] + _pp)


import pytest  # noqa: E402


def shipped_object(name: str):
    """A built-in object (sphere, cube, barrel, fish), or a mesh of
    ``grasp_apso/data/meshes`` by its file name without ``.stl``."""
    from grasp_apso.model.builtin import builtin
    from grasp_apso.model.mesh_files import from_file

    mesh = os.path.join(REPO_ROOT, "grasp_apso", "data", "meshes", f"{name}.stl")
    return from_file(mesh) if os.path.isfile(mesh) else builtin(name)


def plan_allegro_cube(hand, seed: int):
    """(cube, best candidate): ``hand`` planned on the built-in cube resting on a table,
    a small swarm, seed ``seed``."""
    import numpy as np

    from grasp_apso.model.builtin import builtin
    from grasp_apso.model.scene import Scene
    from grasp_apso.search.planner import PlanOptions, plan

    cube = builtin("cube")
    table = Scene.table_under(np.asarray(cube.mesh.vertices))
    result = plan(cube, options=PlanOptions(particles=30, iterations=20, max_grasps=1),
                  rng=np.random.default_rng(seed), hand=hand, scene=table)
    return cube, result.candidates[0]


@pytest.fixture(scope="module")
def allegro_cube_grasp(tmp_path_factory):
    """(hand, cube, best candidate): the Allegro-like URDF hand (mixed mesh and primitive
    links) planned on the built-in cube resting on a table, seed 0, a small swarm
    (:func:`plan_allegro_cube`); the grasp the exact-geometry steps (seating, touching) are
    tested on."""
    from grasp_apso.model.hands.load import load_hand
    from hand_files import write_allegro_like

    hand = load_hand(write_allegro_like(tmp_path_factory.mktemp("hand"), "mixed"))
    return (hand, *plan_allegro_cube(hand, 0))
