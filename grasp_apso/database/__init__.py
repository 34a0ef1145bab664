"""Grasp database: plan mesh collections offline (``grasp_apso_batch``), answer known objects
from it online (:class:`~grasp_apso.database.lookup.GraspDatabase`).

Modules: :mod:`.batch` (the driver: inputs, resume, writes), :mod:`.engines` (local worker
processes, Ray), :mod:`.worker` (one object in a worker), :mod:`.inputs` (files, folders,
manifests), :mod:`.store` (the directory, atomic part files, the writer lock),
:mod:`.schema` (the tables), :mod:`.lookup` (the reader for the node). Nothing here imports
rclpy; pyarrow is needed, Ray only for ``--ray``.

A database is a directory (``DB/_grasp_database.json`` marker, ``DB/grasps/part-*.parquet``,
``DB/_failures/part-*.parq``, ``DB/_LOCK`` while a batch writes) that Parquet readers open
as the grasps table as it is: ``pyarrow.parquet.read_table(DB)``, ``pandas.read_parquet(DB)``
and Spark skip names starting with ``_`` or ``.``, DuckDB's ``read_parquet('DB/**/*.parquet')``
matches the grasps only (see :mod:`.store`). Part files are only ever added, each
atomically (temporary file + rename), so appending across runs and reading during a batch
are safe.

Table ``grasps`` (one row per grasp; poses in the OBJECT frame; m, rad, s; quaternions x y z w)

========================  ===================  ==============================================
column                    type                 meaning
========================  ===================  ==============================================
object_id                 string               file stem, folder-relative path or manifest id
source_path               string               the mesh file as given to the batch
source_sha256             string               SHA-256 of the file's bytes
scale                     float64              file units x scale = metres
mesh_hash                 string               ``GraspObject.mesh_hash`` (the lookup key)
hand_name                 string               the hand description's ``name``
hand_hash                 string               sha256 of the hand (a general hand's
                                               ``source_hash``, the paper hand's YAML); a
                                               lookup answers only for the same hand
options_key               string               16 hex digits of SHA-256 of ``options``
rank                      int32                0 = best (as planned)
joint_positions           list<float64>        grasp posture, JointState order of the hand
                                               (the paper hand: 18, its wrist angles of the
                                               object frame; a general hand: its actuated
                                               joints)
pre_grasp_positions       list<float64>        open pre-shape, same joints
wrist_position            float64[3]           palm (root link) at the grasp (``wrist_in_object``)
wrist_quaternion          float64[4]
pre_grasp_position        float64[3]           wrist retreated by approach_distance
pre_grasp_quaternion      float64[4]
approach                  float64[3]           unit approach direction (palm +z)
approach_distance         float64              m
grasp_quality             float64              ranking score in [0, 1]
fitness, epsilon          float64              swarm fitness, Ferrari-Canny epsilon
force_closure, valid      bool
scene_distance            float64              m, least hand-scene distance as planned (inf)
sim_result                int8                 -1 not simulated, 0 dropped, 1 held
sim_max_shift             float64              m (NaN when not simulated)
sim_max_turn              float64              rad (NaN when not simulated)
contact_points            list<float64[3]>     fingertip contacts, object frame
contact_normals           list<float64[3]>     outward unit normals
contact_fingers           list<string>         finger of each contact
options                   string               JSON: plan options, hand, table, pose
seed                      int64                ``np.random.default_rng(seed)`` replays it
package_version           string               grasp_apso version that planned it
planning_time             float64              s (preparation + search) in the worker
created                   timestamp[us, UTC]
========================  ===================  ==============================================

Table ``failures`` (``DB/_failures``, one row per failed attempt): object_id, source_path,
source_sha256 (null when the file could not be read), scale, hand_name, options_key,
error_type, error (the message, naming the field), retry (False: deterministic, skipped by
a rerun unless ``--retry-failed``), package_version, created.

Schema version 2 (this one) added ``hand_hash`` and variable-length joint vectors; files of
version 1 are read as the shipped paper hand's rows.
"""

from .lookup import GraspDatabase

__all__ = ["GraspDatabase"]
