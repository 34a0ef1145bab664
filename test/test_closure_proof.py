"""Force closure proven without the hull (grasp_apso.quality.closure_proof), checked
against qhull's epsilon (scipy.spatial.ConvexHull through hull_epsilon) on contacts
sampled on real meshes: the proof never contradicts the hull, and its lazy value is the
hull's value."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from grasp_apso.model.builtin import builtin
from grasp_apso.model.mesh_files import from_file
from grasp_apso.quality.closure_proof import CERTIFIED_EPS, Epsilon, closure_certificate, epsilon_lower_bound
from grasp_apso.quality.measures import closure_wrenches, hull_epsilon
from grasp_apso.quality.robustness import normal_uncertainty, robust_wrenches

MUG = Path(__file__).resolve().parents[1] / "grasp_apso" / "data" / "meshes" / "mug.stl"


def _wrench_sets(obj, rng, count):
    """(nominal wrenches, robust wrenches) of ``count`` grasps of 3-5 contacts sampled on the
    object's surface (outward normals of their faces)."""
    points, faces = trimesh.sample.sample_surface(obj.mesh, 4 * count * 5, seed=int(rng.integers(1 << 31)))
    normals = obj.mesh.face_normals[faces]
    sets, k = [], 0
    for _ in range(count):
        n = int(rng.integers(3, 6))
        p, nrm = points[k:k + n], normals[k:k + n]
        k += n
        com, scale = np.asarray(obj.center_of_mass, float), float(obj.characteristic_radius)
        sets.append(closure_wrenches(p, nrm, com, 0.5, torque_scale=scale))
        sets.append(robust_wrenches(obj, p, nrm, 0.5, normal_uncertainty(obj, p), torque_scale=scale))
    return [w for w in sets if w is not None]


@pytest.mark.parametrize("name", ["cube", "sphere", "mug"])
def test_the_proof_never_contradicts_the_hull_and_decides_most_grasps(name):
    obj = from_file(MUG) if name == "mug" else builtin(name)
    rng = np.random.default_rng(7)
    sets = _wrench_sets(obj, rng, 150)
    closure = decided = 0
    for w in sets:
        eps = hull_epsilon(w)
        assert epsilon_lower_bound(w) <= eps + 1e-12  # a lower bound
        verdict = closure_certificate(w)
        if verdict is True:
            assert eps > CERTIFIED_EPS
        elif verdict is False:
            assert eps == 0.0
        lazy = Epsilon(w)
        assert lazy.force_closure == (eps > 0.0)
        assert lazy.value == eps  # the same hull, bit for bit
        closure += eps > 0.0
        decided += verdict is True
    assert closure >= 20, closure  # the sample holds force-closure grasps to prove
    assert decided >= 0.9 * closure, (decided, closure)


def test_collinear_contacts_are_left_to_the_hull():
    """Contacts on one line exert no moment about it: the origin lies on the hull's
    boundary (epsilon 0), where no proof may claim force closure."""
    points = np.array([[-0.03, 0.0, 0.0], [0.0, 0.0, 0.0], [0.03, 0.0, 0.0]])
    normals = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    w = closure_wrenches(points, normals, np.zeros(3), 0.5, torque_scale=0.05)
    assert hull_epsilon(w) == 0.0
    assert closure_certificate(w) is not True
    assert not Epsilon(w).force_closure and Epsilon(w).value == 0.0


def test_an_epsilon_without_wrenches_or_with_a_known_value():
    assert not Epsilon(None).force_closure and Epsilon(None).value == 0.0
    known = Epsilon.known(0.12)
    assert known.force_closure and known.value == 0.12
    assert not Epsilon.known(0.0).force_closure
