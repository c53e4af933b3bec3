import numpy as np
import torch
from synthetic import make_scene

from trajpref.models.encoder import SocialEncoder, scene_features
from trajpref.types import Scene, collate


def _shifted(scene: Scene, offset) -> Scene:
    off = np.asarray(offset, np.float32)
    return Scene(scene.history + off, scene.future + off, scene.agent_type, scene.scene_id)


def _scenes():
    return [make_scene(3, seed=0), make_scene(2, seed=1)]  # N = 5, B = 2, P = 3


def test_feature_shapes_and_relative_history():
    batch = collate(_scenes())
    f = scene_features(batch, 1.0)
    assert f.hist.shape == (5, 8, 4)  # [N, T_h, rel xy + vel xy]
    assert f.geom.shape == (2, 3, 3, 4)  # [B, P, P, 4]
    assert f.mask.tolist() == [[True, True, True], [True, True, False]]
    assert f.slot.tolist() == [0, 1, 2, 0, 1]
    assert torch.equal(f.hist[:, -1, :2], torch.zeros(5, 2))  # last observation is the origin
    assert torch.equal(f.hist[:, 0, 2:], torch.zeros(5, 2))  # first velocity is zero
    # rel and velocity by hand for one agent
    h = batch.history[4]  # [T_h, 2]
    torch.testing.assert_close(f.hist[4, :, :2], h - h[-1])
    torch.testing.assert_close(f.hist[4, 1:, 2:], h[1:] - h[:-1])


def test_features_are_translation_invariant():
    scenes = _scenes()
    f = scene_features(collate(scenes), 1.0)
    g = scene_features(collate([scenes[0], _shifted(scenes[1], [100.0, -40.0])]), 1.0)
    torch.testing.assert_close(g.hist, f.hist, atol=1e-4, rtol=0)
    real = f.mask[:, :, None] & f.mask[:, None, :]  # [B, P, P] pairs of real agents
    torch.testing.assert_close(g.geom[real], f.geom[real], atol=1e-4, rtol=0)
    # (padded pairs hold 0 - state_i, which the attention mask hides)


def test_features_scale_as_one_over_scale():
    batch = collate(_scenes())
    f1, f4 = scene_features(batch, 1.0), scene_features(batch, 4.0)
    torch.testing.assert_close(f4.hist, f1.hist / 4)
    torch.testing.assert_close(f4.geom, f1.geom / 4)


def test_geom_is_j_minus_i():
    batch = collate(_scenes())
    scale = 2.0
    f = scene_features(batch, scale)
    vel = (batch.history[:, -1] - batch.history[:, -2]) / scale  # [N, 2]
    state = torch.cat([batch.origin / scale, vel], -1)  # [N, 4]
    for b, members in ((0, [0, 1, 2]), (1, [3, 4])):
        for i, ai in enumerate(members):
            for j, aj in enumerate(members):
                torch.testing.assert_close(f.geom[b, i, j], state[aj] - state[ai])
    assert torch.equal(f.geom[0].diagonal(dim1=0, dim2=1), torch.zeros(4, 3))


def _encoder(seed: int = 0) -> SocialEncoder:
    torch.manual_seed(seed)
    return SocialEncoder(t_hist=8, hidden=16, layers=2, heads=2)


def test_encoder_output_shape():
    out = _encoder()(scene_features(collate(_scenes()), 1.0))
    assert out.shape == (5, 16)  # [N, H]
    assert torch.isfinite(out).all()


def test_encoder_never_mixes_scenes():
    enc = _encoder()
    scenes = _scenes()
    out = enc(scene_features(collate(scenes), 1.0))
    other = make_scene(2, seed=7)  # a different scene 1, same size
    out2 = enc(scene_features(collate([scenes[0], other]), 1.0))
    torch.testing.assert_close(out2[:3], out[:3], rtol=0, atol=0)
    assert not torch.allclose(out2[3:], out[3:])
    # a scene encoded alone gets the same encodings as inside a batch
    alone = enc(scene_features(collate([scenes[1]]), 1.0))
    torch.testing.assert_close(alone, out[3:], atol=1e-6, rtol=1e-5)


def test_encoder_agents_interact_within_a_scene():
    enc = _encoder()
    scene = make_scene(3)
    out = enc(scene_features(collate([scene]), 1.0))
    moved = Scene(scene.history.copy(), scene.future, scene.agent_type, scene.scene_id)
    moved.history[2] += np.linspace(0, 1, 8, dtype=np.float32)[:, None]  # only agent 2 moves
    out2 = enc(scene_features(collate([moved]), 1.0))
    assert not torch.allclose(out2[0], out[0])  # agent 0 sees agent 2


def test_encoder_is_permutation_equivariant_within_a_scene():
    enc = _encoder()
    scene = make_scene(3)
    perm = [2, 0, 1]
    permuted = Scene(scene.history[perm], scene.future[perm], scene.agent_type[perm], "p")
    out = enc(scene_features(collate([scene]), 1.0))
    out_p = enc(scene_features(collate([permuted]), 1.0))
    torch.testing.assert_close(out_p, out[perm], atol=1e-5, rtol=1e-5)


def test_encoder_is_translation_invariant():
    enc = _encoder()
    scenes = _scenes()
    out = enc(scene_features(collate(scenes), 1.0))
    shifted = [scenes[0], _shifted(scenes[1], [100.0, -40.0])]  # scene 1 has a padded slot
    out2 = enc(scene_features(collate(shifted), 1.0))
    torch.testing.assert_close(out2, out, atol=1e-4, rtol=1e-4)


def test_pair_distance_and_closing_speed_by_hand():
    from trajpref.models.encoder import with_distance

    geom = torch.tensor([[3.0, 4.0, -0.6, -0.8], [0.0, 0.0, 1.0, 0.0]])  # approaching; itself
    out = with_distance(geom, eps=0.0 + 1e-6)
    torch.testing.assert_close(out[:, :4], geom)
    torch.testing.assert_close(out[0, 4:], torch.tensor([5.0, -1.0]))  # 5 m apart, 1 m/s closer
    assert torch.isfinite(out[1]).all() and out[1, 4] < 1e-5 and out[1, 5] == 0


def test_an_encoder_with_pair_distances_reads_six_features_and_still_never_mixes_scenes():
    torch.manual_seed(0)
    enc = SocialEncoder(8, 16, 1, 2, pair_distance=True).eval()
    assert enc.layers[0].edge[0].in_features == 6
    f = scene_features(collate(_scenes()), 1.0)
    other = collate([make_scene(3, seed=0), make_scene(2, seed=5)])  # scene 1 changed
    with torch.no_grad():
        a, b = enc(f), enc(scene_features(other, 1.0))
    torch.testing.assert_close(a[:3], b[:3])  # scene 0's agents do not see scene 1
    assert not torch.allclose(a[3:], b[3:])
