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
