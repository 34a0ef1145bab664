"""ament_python set-up of grasp_apso.

Standard ROS 2 layout: ``colcon build`` and ``pip install .`` both install the python
package, the console scripts, the ament index marker and package.xml. The interface
package ``grasp_apso_interfaces`` (folder ``srv_defs/``) is a separate ament_cmake
package and is deliberately not part of this distribution.
"""
from glob import glob
import os
import xml.etree.ElementTree as ET

from setuptools import find_packages, setup

package_name = 'grasp_apso'
_here = os.path.dirname(os.path.abspath(__file__))
# One version, in package.xml.
version = ET.parse(os.path.join(_here, 'package.xml')).getroot().findtext('version').strip()

setup(
    name=package_name,
    version=version,
    packages=find_packages(include=[package_name, package_name + '.*']),
    # Hand description and other data read through importlib.resources, so they work
    # without the ament index (pip install, pip install -e, colcon).
    package_data={package_name: ['data/*.yaml', 'data/meshes/*.stl', 'data/meshes/*.json', 'data/meshes/*.md']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml') + glob('config/*.xml'))),
        ('share/' + package_name + '/urdf', sorted(glob('urdf/*.urdf'))),
    ],
    # Dependencies are declared in package.xml (rosdep) and pinned in requirements.txt
    # (venv set-up); listing them here would make console scripts of a colcon install
    # check pip distribution names that apt packages do not provide.
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},
    zip_safe=True,
    maintainer='grasp_apso developers',
    maintainer_email='dev@grasp-apso.local',
    description='Precision grasp planning with Adaptive Particle Swarm Optimization '
                '(APSO) for a five-fingered hand: ROS 2 node, Python library and CLI.',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'planner_node = grasp_apso.ros.node:main',
            'grasp_apso_plan = grasp_apso.tools.cli:main',
            'grasp_apso_urdf = grasp_apso.tools.urdf_cli:main',
            'grasp_apso_batch = grasp_apso.tools.batch_cli:main',
            'grasp_apso_hand = grasp_apso.tools.hand_cli:main',
        ],
    },
)
