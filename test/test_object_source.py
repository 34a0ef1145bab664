"""The one object resolver (issue 19.2): every source kind gives the same validated object
the direct builders give, errors name the field the caller filled, and the cache keys on
content (inline meshes) or on path, time and size (files)."""
import os

import numpy as np
import pytest

from grasp_apso.cache import BoundedCache
from grasp_apso.errors import ObjectError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.object_source import BuiltinObject, InlineMesh, MeshFile, resolve_object


def _cube():
    return builtin('cube').mesh


def test_every_source_kind_gives_the_object_of_its_direct_builder(tmp_path):
    mesh = _cube()
    path = tmp_path / 'cube.stl'
    mesh.export(str(path))
    stages = []
    inline = resolve_object(InlineMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)), on_stage=stages.append)
    from_file = resolve_object(MeshFile(str(path), allowed_dir=str(tmp_path)), on_stage=stages.append)
    named = resolve_object(BuiltinObject('cube'))
    from grasp_apso.model.mesh_files import from_file as direct_file
    from grasp_apso.model.objects import from_arrays

    assert inline.mesh_hash == from_arrays(mesh.vertices, mesh.faces).mesh_hash
    assert from_file.mesh_hash == direct_file(str(path)).mesh_hash
    np.testing.assert_allclose([inline.mesh.volume, from_file.mesh.volume], 0.07 ** 3, rtol=1e-5)
    assert named.name == 'cube'
    assert stages == ['validation', 'reading', 'validation']


def test_a_scaled_file_is_the_scaled_mesh(tmp_path):
    path = tmp_path / 'cube.stl'
    _cube().export(str(path))
    obj = resolve_object(MeshFile(str(path), scale=0.5))
    np.testing.assert_allclose(np.ptp(np.asarray(obj.mesh.vertices), axis=0), [0.035] * 3, atol=1e-7)
    with pytest.raises(ObjectError, match='mesh_scale'):
        resolve_object(MeshFile(str(path), scale=0.0))


def test_errors_name_the_field_of_the_source(tmp_path):
    vertices = np.array([[0, 0, 0], [np.nan, 0, 0], [0, 0.05, 0], [0, 0, 0.05]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    with pytest.raises(ObjectError, match=r'^mesh: vertex 1'):
        resolve_object(InlineMesh(vertices, faces))
    with pytest.raises(ObjectError, match=r'^mesh_vertices \(packed mesh\): vertex 1'):
        resolve_object(InlineMesh(vertices, faces, packed=True))
    outside = tmp_path / 'outside.stl'
    _cube().export(str(outside))
    allowed = tmp_path / 'allowed'
    allowed.mkdir()
    with pytest.raises(ObjectError, match=r'^mesh_uri'):
        resolve_object(MeshFile(str(outside), allowed_dir=str(allowed), shown='outside.stl'))
    with pytest.raises(ObjectError, match=r'^object_name'):
        resolve_object(BuiltinObject('teapot'))


def test_the_cache_keys_on_content_and_on_the_file_state(tmp_path):
    cache = BoundedCache(8, 10 ** 8)
    mesh = _cube()
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    first = resolve_object(InlineMesh(v.copy(), f.copy()), cache=cache)
    assert resolve_object(InlineMesh(v.copy(), f.copy()), cache=cache) is first  # equal content, new arrays
    assert resolve_object(InlineMesh(v * 1.5, f), cache=cache) is not first
    path = tmp_path / 'shape.stl'
    mesh.export(str(path))
    a = resolve_object(MeshFile(str(path)), cache=cache)
    assert resolve_object(MeshFile(str(path)), cache=cache) is a
    bigger = mesh.copy()
    bigger.apply_scale(2.0)
    bigger.export(str(path))
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10 ** 9))
    b = resolve_object(MeshFile(str(path)), cache=cache)
    assert b is not a and b.mesh_hash != a.mesh_hash
