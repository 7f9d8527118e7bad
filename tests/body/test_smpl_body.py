"""SMPL-family loader, on a small model file the test writes in the real SMPL pickle format."""

import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse

from loosefit.body.smpl_body import Y_UP_TO_Z_UP, SMPLBody, read_smpl_file
from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion import Motion

J = 24


def write_smpl_pkl(path, posedirs_scale=0.0, seed=0):
    """A tiny SMPL model: 24 joints on a chain, 3 vertices per joint, in SMPL's real pickle layout
    (scipy sparse J_regressor, kintree_table whose root parent is 2**32 - 1, latin1-compatible pickle)."""
    rng = np.random.default_rng(seed)
    parents = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21])
    joints = np.zeros((J, 3))
    for j in range(1, J):  # SMPL frame: Y up; children spread below/above their parent
        joints[j] = joints[parents[j]] + rng.normal(0, 0.1, 3) + np.array([0, 0.1 if j in (3, 6, 9, 12, 15) else -0.1, 0])
    V = 3 * J
    v_template = np.repeat(joints, 3, axis=0) + rng.normal(0, 0.02, (V, 3))
    weights = np.zeros((V, J))
    weights[np.arange(V), np.arange(V) // 3] = 1.0
    # The regressor averages each joint's three vertices exactly onto the joint: offset them symmetrically.
    for j in range(J):
        v_template[3 * j : 3 * j + 3] -= v_template[3 * j : 3 * j + 3].mean(0) - joints[j]
    J_reg = scipy.sparse.csc_matrix(np.kron(np.eye(J), np.ones((1, 3)) / 3))
    kintree = np.stack([parents, np.arange(J)]).astype(np.uint32)
    kintree[0, 0] = 2**32 - 1
    faces = np.array([[3 * j, 3 * j + 1, 3 * j + 2] for j in range(J)], dtype=np.uint32)
    model = {
        "v_template": v_template,
        "shapedirs": rng.normal(0, 0.01, (V, 3, 10)),
        "posedirs": rng.normal(0, posedirs_scale, (V, 3, 207)) if posedirs_scale else np.zeros((V, 3, 207)),
        "J_regressor": J_reg,
        "weights": weights,
        "kintree_table": kintree,
        "f": faces,
        "bs_type": "lrotmin",
        "bs_style": "lbs",
    }
    with open(path, "wb") as f:
        pickle.dump(model, f, protocol=2)
    return model


@pytest.fixture
def smpl_file(tmp_path):
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    return path, write_smpl_pkl(path)


def motion_for(body, rotations, translation=None):
    T = rotations.shape[0]
    trans = np.repeat(body.rest_root_position()[None], T, 0) if translation is None else translation
    return Motion(rotations, trans, rig=body.rig, joint_names=body.joint_names)


def test_rest_geometry_in_loosefit_frame(smpl_file):
    path, model = smpl_file
    body = SMPLBody(path)
    assert body.rig == "smpl" and body.num_joints == 24 and body.joint_names[18] == "left_elbow"
    rest = body.rest_verts()
    expected = model["v_template"] @ Y_UP_TO_Z_UP.T
    offset = rest - expected
    assert np.allclose(offset, offset[0], atol=1e-6)  # a pure translation of the Y-up template
    assert rest[:, 2].min() == pytest.approx(0, abs=1e-6) and np.allclose(body.rest_joints()[0, :2], 0, atol=1e-6)
    posed = body.pose(body.rest_motion(2))
    assert np.abs(posed.verts - rest).max() < 1e-6


def test_single_joint_rotation_closed_form(smpl_file):
    path, _ = smpl_file
    body = SMPLBody(path)
    k = body.joint_names.index("left_knee")
    aa = np.zeros((1, J, 3))
    aa[0, k] = [0.7, -0.2, 0.3]
    aa[0, 0] = [0.0, 0.0, 0.5]  # root yaw about +Z (loosefit's up)
    trans = body.rest_root_position()[None] + np.array([[0.3, -0.1, 0.2]])
    posed = body.pose(motion_for(body, aa, trans))
    rest_v, rest_j = body.rest_verts(), body.rest_joints()
    Rr = axis_angle_to_matrix(aa[0, 0]).numpy()
    Rk = axis_angle_to_matrix(aa[0, k]).numpy()
    # Vertices skinned to the knee: rotate about the knee by Rk, then the whole body about the root by Rr.
    local = rest_j[k] + (rest_v[3 * k : 3 * k + 3] - rest_j[k]) @ Rk.T
    expected = trans[0] + (local - rest_j[0]) @ Rr.T
    assert np.abs(posed.verts[0, 3 * k : 3 * k + 3] - expected).max() < 1e-5
    assert np.abs(posed.joints[0, k] - (trans[0] + (rest_j[k] - rest_j[0]) @ Rr.T)).max() < 1e-5


def test_pose_corrective_blend_shapes_are_applied(tmp_path):
    path = tmp_path / "SMPL_POSEDIRS.pkl"
    model = write_smpl_pkl(path, posedirs_scale=0.01)
    body = SMPLBody(path)
    aa = np.zeros((1, J, 3))
    aa[0, 5] = [0.4, 0.1, -0.2]  # right knee
    posed = body.pose(motion_for(body, aa))
    # Root vertices keep an identity transform, so they move by exactly the pose blend shape (in SMPL's frame).
    C = Y_UP_TO_Z_UP
    R_smpl = C.T @ axis_angle_to_matrix(aa[0, 5]).numpy() @ C
    feature = np.zeros((23, 9))
    feature[4] = (R_smpl - np.eye(3)).reshape(-1)  # joint 5 is the 5th non-root joint
    delta = model["posedirs"][:3].reshape(9, 207) @ feature.reshape(-1)
    assert np.abs(posed.verts[0, :3] - body.rest_verts()[:3] - delta.reshape(3, 3) @ C.T).max() < 1e-6


def test_bad_model_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        SMPLBody(tmp_path / "missing.pkl")
    bad = tmp_path / "bad.pkl"
    bad.write_bytes(b"not a pickle")
    with pytest.raises(InputError, match="bad.pkl"):
        SMPLBody(bad)
    partial = tmp_path / "partial.npz"
    np.savez(partial, v_template=np.zeros((3, 3)))
    with pytest.raises(InputError, match="missing"):
        SMPLBody(partial)


class _Payload:
    """Unpickling this creates the file ``path`` (a crafted model file could run any code this way)."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _plain_arrays(model):
    return {k: v.toarray() if scipy.sparse.issparse(v) else np.asarray(v) for k, v in model.items()}


def test_crafted_npz_runs_no_code(tmp_path):
    model = write_smpl_pkl(tmp_path / "ref.pkl")
    marker, path = tmp_path / "marker", tmp_path / "evil.npz"
    np.savez(path, **{**_plain_arrays(model), "v_template": np.array([_Payload(marker)], dtype=object)})
    with pytest.raises(InputError, match=r"evil.npz: .*array 'v_template' holds pickled Python objects") as err:
        SMPLBody(path)
    assert not marker.exists() and "convert it to .npz" not in str(err.value)
    np.load(path, allow_pickle=True)["v_template"]  # the payload is live: unpickled, it writes the marker
    assert marker.exists()


@pytest.mark.parametrize("protocol", [0, 2, 5])
def test_crafted_pickle_runs_no_code(tmp_path, protocol):
    model = write_smpl_pkl(tmp_path / "ref.pkl")
    marker, path = tmp_path / "marker", tmp_path / "evil.pkl"
    with open(path, "wb") as f:
        pickle.dump({**model, "v_template": _Payload(marker)}, f, protocol=protocol)
    with pytest.raises(InputError, match=r"evil.pkl: the pickle asks for (builtins|io).open, .*refused"):
        SMPLBody(path)
    assert not marker.exists()
    with open(path, "rb") as f:
        pickle.load(f)  # the payload is live
    assert marker.exists()


@pytest.mark.parametrize("protocol", [0, 2, 5])
def test_legit_pickles_of_every_protocol_load(tmp_path, protocol):
    """numpy arrays, a scipy.sparse J_regressor and Python 2 style names are all a SMPL file needs."""
    model = write_smpl_pkl(tmp_path / "ref.pkl")
    path = tmp_path / f"SMPL_{protocol}.pkl"
    with open(path, "wb") as f:
        pickle.dump(model, f, protocol=protocol)
    body, ref = SMPLBody(path), SMPLBody(tmp_path / "ref.pkl")
    assert np.array_equal(body.rest_verts(), ref.rest_verts()) and body.num_betas == 10


def test_original_chumpy_pickle_reads_without_chumpy(tmp_path, monkeypatch):
    """Original SMPL files hold chumpy arrays: read as their values, without importing chumpy."""
    module = types.ModuleType("chumpy.ch")

    class Ch:  # chumpy's pickled layout: NEWOBJ of chumpy.ch.Ch, then a state dict with the array as 'x'
        def __init__(self, x):
            self.x, self._dirty_vars, self._itr = x, set(), None

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    module.Ch = Ch
    model = write_smpl_pkl(tmp_path / "ref.pkl", posedirs_scale=0.01)
    path = tmp_path / "SMPL_chumpy.pkl"
    with monkeypatch.context() as m:  # chumpy exists only while the file is written
        m.setitem(sys.modules, "chumpy", types.ModuleType("chumpy"))
        m.setitem(sys.modules, "chumpy.ch", module)
        with open(path, "wb") as f:
            pickle.dump({**model, "shapedirs": Ch(model["shapedirs"]), "posedirs": Ch(model["posedirs"])}, f, protocol=2)
    assert "chumpy.ch" not in sys.modules or sys.modules["chumpy.ch"] is not module
    data = read_smpl_file(path)
    assert np.array_equal(data["shapedirs"], model["shapedirs"]) and np.array_equal(data["posedirs"], model["posedirs"])
    assert np.array_equal(SMPLBody(path).rest_verts(), SMPLBody(tmp_path / "ref.pkl").rest_verts())


def test_pickles_that_are_no_model(tmp_path):
    path = tmp_path / "list.pkl"
    path.write_bytes(pickle.dumps([1, 2, 3]))
    with pytest.raises(InputError, match="list.pkl: not a SMPL-family model file .a pickled list"):
        SMPLBody(path)
    model = write_smpl_pkl(tmp_path / "ref.pkl")
    path.write_bytes(pickle.dumps({**model, "weights": "heavy"}))
    with pytest.raises(InputError, match="list.pkl: not a SMPL-family model file: an array is not numeric"):
        SMPLBody(path)
    truncated = tmp_path / "cut.pkl"
    truncated.write_bytes((tmp_path / "ref.pkl").read_bytes()[:500])
    with pytest.raises(InputError, match="cut.pkl: cannot read SMPL model file"):
        SMPLBody(truncated)
