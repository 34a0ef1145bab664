"""Packaging of grasp_apso: tests import the working tree, and the installed package is
a standard ament_python package (ament index marker, package.xml, console scripts)
that does not carry the interface package srv_defs/.
"""
import importlib.metadata
import os
import sys
import xml.etree.ElementTree as ET

import grasp_apso

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _package_xml(path):
    return ET.parse(os.path.join(REPO_ROOT, path)).getroot()


def test_tests_import_the_working_tree():
    assert os.path.dirname(os.path.abspath(grasp_apso.__file__)) == os.path.join(REPO_ROOT, 'grasp_apso')
    # Ray, once imported (test_database), puts its vendored ray/thirdparty_files first on
    # sys.path; it holds Ray's own dependencies, never grasp_apso.
    site_dirs = [i for i, p in enumerate(sys.path) if 'site-packages' in p and 'thirdparty_files' not in p]
    assert sys.path.index(REPO_ROOT) < min(site_dirs, default=len(sys.path))
    assert os.environ['PYTHONPATH'].split(os.pathsep)[0] == REPO_ROOT


def test_package_xml():
    root = _package_xml('package.xml')
    assert root.get('format') == '3'
    assert root.findtext('name') == 'grasp_apso'
    assert root.findtext('version') == grasp_apso.__version__
    assert root.findtext('export/build_type') == 'ament_python'
    exec_deps = {e.text for e in root.findall('exec_depend')}
    assert {'rclpy', 'grasp_apso_interfaces', 'geometry_msgs', 'sensor_msgs', 'shape_msgs',
            'visualization_msgs', 'python3-numpy'} <= exec_deps


def test_interface_package_xml():
    root = _package_xml('srv_defs/package.xml')
    assert root.get('format') == '3'
    assert root.findtext('name') == 'grasp_apso_interfaces'
    assert root.findtext('export/build_type') == 'ament_cmake'
    assert root.findtext('member_of_group') == 'rosidl_interface_packages'


def test_installed_distribution():
    dist = importlib.metadata.distribution('grasp_apso')
    assert dist.version == grasp_apso.__version__
    scripts = {ep.name: ep.value for ep in dist.entry_points if ep.group == 'console_scripts'}
    assert scripts == {'planner_node': 'grasp_apso.ros.node:main',
                       'grasp_apso_plan': 'grasp_apso.tools.cli:main',
                       'grasp_apso_urdf': 'grasp_apso.tools.urdf_cli:main',
                       'grasp_apso_batch': 'grasp_apso.tools.batch_cli:main',
                       'grasp_apso_hand': 'grasp_apso.tools.hand_cli:main'}
    # pip (RECORD) or colcon (egg-info SOURCES.txt) file lists; the share/ files are
    # checked through the ament index below.
    files = [str(f) for f in dist.files or []]
    assert any(f.replace(os.sep, '/').endswith('grasp_apso/__init__.py') for f in files)
    # package data: the hand, the real meshes with their sources and licence
    for name in ('grasp_apso/data/hand.yaml', 'grasp_apso/data/meshes/mug.stl',
                 'grasp_apso/data/meshes/SOURCES.md', 'grasp_apso/data/meshes/manifest.json'):
        assert any(f.replace(os.sep, '/').endswith(name) for f in files), name
    assert not [f for f in files if 'srv_defs' in f or 'grasp_apso_interfaces' in f], \
        'the ament_python package must not install the interface package'


def test_ament_index_finds_both_packages():
    from ament_index_python.packages import get_package_share_directory

    os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    share = get_package_share_directory('grasp_apso')
    assert os.path.isfile(os.path.join(share, 'package.xml'))
    assert os.path.isfile(os.path.join(share, 'urdf', 'apso_paper_hand.urdf'))
    index = os.path.join(share, '..', 'ament_index', 'resource_index', 'packages', 'grasp_apso')
    assert os.path.isfile(index)
    iface_share = get_package_share_directory('grasp_apso_interfaces')
    for rel in ('msg/Grasp.msg', 'msg/GraspProgress.msg', 'srv/PlanGrasp.srv', 'action/PlanGrasp.action'):
        assert os.path.isfile(os.path.join(iface_share, rel)), rel
