import math

import pytest
import torch
from torch import nn

from trajpref.errors import ConfigError
from trajpref.models.layers import (
    SetAttention,
    SocialAttention,
    direct_social_attention,
    mlp,
    timestep_embedding,
)


def test_mlp_sizes_and_activations():
    net = mlp([3, 5, 7])
    assert [type(m) for m in net] == [nn.Linear, nn.SiLU, nn.Linear]
    assert (net[0].in_features, net[0].out_features) == (3, 5)
    assert (net[2].in_features, net[2].out_features) == (5, 7)
    assert net(torch.zeros(4, 3)).shape == (4, 7)

    net = mlp([2, 4, 4, 1], act=nn.ReLU, final_act=True)
    assert [type(m) for m in net] == [nn.Linear, nn.ReLU] * 3
    assert (net(torch.randn(10, 2)) >= 0).all()  # a final ReLU clips the output


def test_timestep_embedding_at_zero_is_cos_one_sin_zero():
    emb = timestep_embedding(torch.zeros(2, 3, dtype=torch.long), 8)
    assert emb.shape == (2, 3, 8)
    assert torch.equal(emb[..., :4], torch.ones(2, 3, 4))  # cos(0)
    assert torch.equal(emb[..., 4:], torch.zeros(2, 3, 4))  # sin(0)


def test_timestep_embedding_hand_computed():
    # dim 4: frequencies 1 and 1000^(-1/2)
    emb = timestep_embedding(torch.tensor(3), 4)
    f = 1000**-0.5
    expected = torch.tensor([math.cos(3), math.cos(3 * f), math.sin(3), math.sin(3 * f)])
    torch.testing.assert_close(emb, expected)


def _attention_inputs(b: int, p: int, hidden: int = 8, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    h = torch.randn(b, p, hidden, generator=g)  # [B, P, H]
    geom = torch.randn(b, p, p, 4, generator=g)  # [B, P, P, 4]
    return h, geom


def test_padding_never_influences_real_agents():
    torch.manual_seed(0)
    layer = SocialAttention(8, 2)
    h, geom = _attention_inputs(1, 4)
    mask = torch.tensor([[True, True, True, False]])  # slot 3 is padding
    out = layer(h, geom, mask)

    h2, geom2 = h.clone(), geom.clone()
    h2[:, 3] = 100 * torch.randn(8)  # padded row's values ...
    geom2[:, :, 3] = -50.0  # ... its geometry as a key/value ...
    geom2[:, 3, :] = 77.0  # ... and as a query
    out2 = layer(h2, geom2, mask)
    torch.testing.assert_close(out2[:, :3], out[:, :3], rtol=0, atol=0)
    assert not torch.allclose(out2[:, 3], out[:, 3])  # the padded slot itself did change

    # the same real agents without any padding slot at all give the same outputs
    out3 = layer(h[:, :3], geom[:, :3, :3], mask[:, :3])
    torch.testing.assert_close(out3, out[:, :3])


def test_real_agents_do_attend_to_each_other():
    torch.manual_seed(0)
    layer = SocialAttention(8, 2)
    h, geom = _attention_inputs(1, 3)
    mask = torch.ones(1, 3, dtype=torch.bool)
    out = layer(h, geom, mask)
    h2 = h.clone()
    h2[:, 2] = torch.randn(8)  # (not a constant shift: LayerNorm would remove it)
    assert not torch.allclose(layer(h2, geom, mask)[:, 0], out[:, 0])


def test_no_attention_across_scenes():
    torch.manual_seed(0)
    layer = SocialAttention(8, 2)
    h, geom = _attention_inputs(2, 3)
    mask = torch.tensor([[True, True, True], [True, True, False]])  # 3 + 2 agents
    out = layer(h, geom, mask)

    h2, geom2 = h.clone(), geom.clone()
    h2[1] = torch.randn(3, 8)
    geom2[1] = torch.randn(3, 3, 4)
    out2 = layer(h2, geom2, mask)
    torch.testing.assert_close(out2[0], out[0], rtol=0, atol=0)
    assert not torch.allclose(out2[1, :2], out[1, :2])


def test_factored_attention_matches_the_direct_formula_and_its_gradients():
    torch.manual_seed(0)
    layer = SocialAttention(16, 4)
    h, geom = _attention_inputs(3, 5, hidden=16)
    mask = torch.tensor([[1, 1, 1, 1, 1], [1, 1, 0, 0, 0], [1, 0, 0, 0, 0]], dtype=torch.bool)
    out = layer(h, geom, mask)
    ref = direct_social_attention(layer, h, geom, mask)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    # and the same gradients for every parameter (training follows the same path)
    w = torch.randn_like(out)
    grads = torch.autograd.grad((out * w).sum(), list(layer.parameters()))
    grads_ref = torch.autograd.grad((ref * w).sum(), list(layer.parameters()))
    for g, g_ref in zip(grads, grads_ref, strict=True):
        torch.testing.assert_close(g, g_ref, rtol=1e-4, atol=1e-5)


def test_residual_dropout_drops_in_training_only_and_matches_the_direct_formula():
    torch.manual_seed(0)
    plain, dropped = SocialAttention(16, 4), SocialAttention(16, 4, dropout=0.5)
    dropped.load_state_dict(plain.state_dict())  # no parameters of its own
    h, geom = _attention_inputs(2, 4, hidden=16)
    mask = torch.tensor([[1, 1, 1, 1], [1, 1, 0, 0]], dtype=torch.bool)
    plain.eval()
    dropped.eval()
    torch.testing.assert_close(dropped(h, geom, mask), plain(h, geom, mask), rtol=0, atol=0)
    dropped.train()
    torch.manual_seed(3)
    out = dropped(h, geom, mask)
    torch.manual_seed(3)  # the same masks, drawn in the same order
    ref = direct_social_attention(dropped, h, geom, mask)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    assert not torch.allclose(out, plain(h, geom, mask))


def test_hidden_not_divisible_by_heads_is_a_config_error():
    with pytest.raises(ConfigError, match="divisible"):
        SocialAttention(10, 3)


def test_set_attention_matches_torchs_attention_and_permutes_with_its_tokens():
    torch.manual_seed(0)
    layer = SetAttention(8, 2).eval()
    x = torch.randn(3, 5, 8)  # 3 sets of 5 tokens
    # the same layer through torch's own attention kernel
    s, k, w = x.shape
    q, key, v = layer.qkv(layer.norm1(x)).view(s, k, 3, 2, 4).unbind(2)
    heads = [t.transpose(1, 2) for t in (q, key, v)]  # [S, nh, K, d] each
    att = nn.functional.scaled_dot_product_attention(*heads).transpose(1, 2).reshape(s, k, w)
    ref = x + layer.out(att)
    ref = ref + layer.ff(layer.norm2(ref))
    torch.testing.assert_close(layer(x), ref, atol=1e-5, rtol=1e-5)
    # no positions: permuting a set's tokens permutes its outputs, and sets stay apart
    perm = torch.tensor([4, 0, 3, 1, 2])
    torch.testing.assert_close(layer(x[:, perm]), layer(x)[:, perm], atol=1e-5, rtol=1e-5)
    y = x.clone()
    y[0] += torch.randn(5, 8)
    torch.testing.assert_close(layer(y)[1:], layer(x)[1:])


def test_set_attention_width_not_divisible_by_heads_is_a_config_error():
    with pytest.raises(ConfigError, match="divisible"):
        SetAttention(6, 4)


def test_a_published_generator_predicts_the_same_with_either_form(data_root, monkeypatch):
    """The published zara1 generator (256-wide encoder, two attention layers), trained with
    the direct form, gives the same samples with the factored one on real validation scenes."""
    from trajpref.data import load_dataset
    from trajpref.models import checkpoint as ckpt
    from trajpref.models.encoder import scene_features
    from trajpref.types import collate

    payload = ckpt.load("zara1/generator")
    generator, _ = ckpt.build_generator(payload)
    generator.eval()
    batch = collate(load_dataset("zara1", "val", data_root).scenes[:24])
    features = scene_features(batch, payload["scale"])
    with torch.no_grad():
        factored = generator(features)
        monkeypatch.setattr(SocialAttention, "forward", direct_social_attention)
        direct = generator(features)
    assert features.mask.shape[1] > 1  # scenes with several agents: attention does something
    torch.testing.assert_close(factored.mean, direct.mean, rtol=0, atol=1e-5)
    torch.testing.assert_close(factored.shifts, direct.shifts, rtol=0, atol=1e-4)
    torch.testing.assert_close(factored.log_sigma, direct.log_sigma, rtol=0, atol=1e-5)
