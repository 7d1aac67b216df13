"""The translator's torch side: FK parity with numpy, network shapes, a smoke training run."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motion import canonical as C  # noqa: E402
from motion import features as Fe  # noqa: E402
from motion import kinematics as K  # noqa: E402
from motion import rotations as rot  # noqa: E402
from tests.conftest import data_path  # noqa: E402
from training import fk as tfk  # noqa: E402
from training.translator import data as TD  # noqa: E402
from training.translator import model as M  # noqa: E402


@pytest.fixture(scope="module")
def bandai_clips():
    data_path("bandai", "dataset-1")
    from training.data import load_bandai

    clips = load_bandai(datasets=(1,))
    return [clips[0], clips[len(clips) // 2], clips[-1]]


def test_torch_fk_equals_numpy_fk(bandai_clips):
    for clip in bandai_clips:
        m = clip.motion
        grot, gpos = K.fk(m.lrot, m.lpos, m.skeleton.parents)
        lmat = tfk.matrix_from_quat(torch.tensor(m.lrot, dtype=torch.float64))
        gmat_t, gpos_t = tfk.fk(lmat, torch.tensor(m.lpos, dtype=torch.float64), C.PARENTS)
        scale = np.abs(gpos).max()
        np.testing.assert_allclose(gpos_t.numpy(), gpos, rtol=1e-4, atol=1e-4 * scale)
        np.testing.assert_allclose(gmat_t.numpy(), rot.to_matrix(grot), atol=1e-6)
        # float32, as in training
        gpos32 = tfk.fk(lmat.float(), torch.tensor(m.lpos, dtype=torch.float32), C.PARENTS)[1]
        np.testing.assert_allclose(gpos32.numpy(), gpos, rtol=1e-4, atol=1e-4 * scale)


def test_matrix_from_6d_matches_numpy():
    r6 = np.random.default_rng(0).normal(size=(50, 6))
    ours = tfk.matrix_from_6d(torch.tensor(r6)).numpy()
    np.testing.assert_allclose(ours, rot.to_matrix(rot.from_6d(r6)), atol=1e-9)


def test_root_local_fk_gives_the_3d_style_features(bandai_clips):
    layer = tfk.RootLocalFK().double()
    for clip in bandai_clips:
        enc = Fe.encode(clip.motion)
        content = torch.tensor(enc.content, dtype=torch.float64)
        r6 = content[:, : Fe.OUTPUT_CHANNELS].reshape(-1, len(Fe.BODY), 6)
        positions = layer(r6, content[:, Fe.ROTATION_CHANNELS]).reshape(len(content), -1)
        np.testing.assert_allclose(positions.numpy(), enc.style3d, atol=1e-4)


@pytest.mark.parametrize("frames", [4, 32, 37, 61, 64])
@pytest.mark.parametrize("batch", [1, 3])
@pytest.mark.parametrize("keep_amplitude", [False, True])
def test_network_shapes(frames, batch, keep_amplitude):
    cfg = M.ModelConfig(num_styles=5, keep_amplitude=keep_amplitude)
    g, d = M.Translator(cfg).eval(), M.Discriminator(cfg)
    content = M.pad_time(torch.randn(batch, Fe.CONTENT_CHANNELS, frames))
    padded = content.shape[-1]
    assert padded % M.STRIDE == 0 and padded - frames < M.STRIDE
    style3d = M.pad_time(torch.randn(batch, Fe.STYLE3D_CHANNELS, frames + 5))
    style2d = M.pad_time(torch.randn(batch, Fe.STYLE2D_CHANNELS, 2 * frames))
    with torch.no_grad():
        code = g.content_encoder(content)
        assert code.shape == (batch, cfg.content_channels[-1], padded // 2**cfg.content_down)
        z3, z2 = g.style3d(style3d), g.style2d(style2d)
        assert z3.shape == z2.shape == (batch, cfg.style_dim)
        out = g.decoder(code, z3)
        assert out.shape == (batch, Fe.OUTPUT_CHANNELS, padded)
        assert out[..., :frames].shape[-1] == frames
        scores, feats = d(torch.randn(batch, Fe.STYLE3D_CHANNELS + Fe.OUTPUT_CHANNELS, padded))
        assert scores.shape[:2] == (batch, 5) and feats.shape[0] == batch


def test_smoke_training_writes_a_resumable_checkpoint(tmp_path, monkeypatch):
    data_path("bandai", "dataset-1")
    from training.translator import train as T

    monkeypatch.setenv("MOTION_SMOKE", "1")
    ckpt = tmp_path / "translator.pt"
    args = [
        "--clips-per-style", "3", "--val-fraction", "0.34", "--batch-size", "8", "--views", "2",
        "--checkpoint", str(ckpt), "--log-dir", str(tmp_path / "runs"), "--threads", "1",
    ]  # fmt: skip
    T.main(args)
    assert ckpt.exists()
    assert (tmp_path / "translator_stats.npz").exists()
    assert (tmp_path / "translator_config.json").exists()
    saved = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert saved["step"] == 3 and saved["val_takes"]
    assert set(saved["metrics"]) >= {"rec_pos_cm", "style_acc_3d"}
    T.main(args + ["--resume"])
    resumed = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert resumed["step"] == 6
    assert resumed["val_takes"] == saved["val_takes"]
    g, stats, meta = T.load_translator(ckpt)
    assert meta["step"] == 6 and stats.mean["content"].shape == (Fe.CONTENT_CHANNELS,)
    # content heads join a discriminator trained without them, with an optimizer group
    T.main(args + ["--resume", "--w-content-adv", "0.5"])
    headed = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert headed["step"] == 9 and headed["model_config"]["num_contents"] == len(headed["contents"])
    assert headed["discriminator"]["content_head.weight"].shape[0] == len(headed["contents"]) > 1
    assert [group.get("lr_scale", 1.0) for group in headed["opt_d"]["param_groups"]] == [1.0, 10.0]
    T.main(args + ["--resume"])  # and go on with them
    assert torch.load(ckpt, map_location="cpu", weights_only=False)["step"] == 12
    # kept amplitudes join a generator trained without them, calibrated, with their own group
    T.main(args + ["--resume", "--keep-amplitude"])
    kept = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert kept["step"] == 15 and kept["model_config"]["keep_amplitude"]
    refs = [v for k, v in kept["generator"].items() if k.endswith(".log_ref")]
    assert len(refs) == 9 and all(float(r.abs().max()) > 0 for r in refs)
    assert [group.get("lr_scale", 1.0) for group in kept["opt_g"]["param_groups"]] == [1.0, 10.0]
    T.main(args + ["--resume"])
    again = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert again["step"] == 18 and again["model_config"]["keep_amplitude"]
    # a grown decoder goes on from the same step with its optimizer
    T.main(args + ["--resume", "--grow-decoder", "1"])
    grown = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert grown["step"] == 21 and grown["model_config"]["decoder_resblocks"] == 3
    assert "decoder.res.2.conv2.weight" in grown["generator"]
    # the content-style probe starts fresh, and is kept and resumed with its optimizer
    T.main(args + ["--resume", "--w-content-style", "1.0"])
    probed = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert probed["step"] == 24 and probed["probe"]["weight"].shape[0] == len(probed["styles"])
    assert probed["opt_probe"]["state"]
    T.main(args + ["--resume"])
    reloaded = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert reloaded["step"] == 27
    steps = [float(o["opt_probe"]["state"][0]["step"]) for o in (probed, reloaded)]
    assert steps == [3.0, 6.0]  # Adam went on from the saved state
    # a content bottleneck joins a trained model, and the narrowed model goes on
    T.main(args + ["--resume", "--content-bottleneck", "8"])
    narrowed = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert narrowed["step"] == 30 and narrowed["model_config"]["content_bottleneck"] == 8
    assert narrowed["generator"]["content_encoder.bottleneck.0.weight"].shape[:2] == (8, 160)
    T.main(args + ["--resume"])
    assert torch.load(ckpt, map_location="cpu", weights_only=False)["step"] == 33
    with pytest.raises(SystemExit, match="already has a bottleneck"):
        T.main(args + ["--resume", "--content-bottleneck", "8"])
    # mixed kernels join a trained decoder, and the mixed model goes on with its optimizer
    T.main(args + ["--resume", "--style-kernels", "2"])
    mixed = torch.load(ckpt, map_location="cpu", weights_only=False)
    assert mixed["step"] == 36 and mixed["model_config"]["style_kernels"] == 2
    assert mixed["generator"]["decoder.res.0.conv1.weight"].shape[0] == 2 * 160
    assert mixed["generator"]["decoder.mix.weight"].shape == (3 * 2 * 2, 128)
    T.main(args + ["--resume"])
    assert torch.load(ckpt, map_location="cpu", weights_only=False)["step"] == 39
    with pytest.raises(SystemExit):
        T.main(args + ["--grow-decoder", "1"])  # a fresh run takes its size from the config
    fresh = ["--checkpoint", str(tmp_path / "wide.pt")]  # a fresh run's bottleneck is checked
    with pytest.raises(ValueError, match="content_bottleneck 500 must be 0"):
        T.main(args + fresh + ["--content-bottleneck", "500"])
    with pytest.raises(ValueError, match="style_kernels 1 must be"):
        T.main(args + fresh + ["--style-kernels", "1"])
    # a run whose validation reconstruction drifts past diverged_factor x its best stops
    # and leaves the last checkpoint as it was (a factor under 1 trips at the first check)
    before = ckpt.read_bytes()
    with pytest.raises(SystemExit, match="diverged at step 42: validation rec_pos_cm"):
        T.main(args + ["--resume", "--diverged-factor", "0.5"])
    assert ckpt.read_bytes() == before


def test_kept_amplitude_starts_as_instance_norm_and_can_hand_on_a_spans_amplitude():
    torch.manual_seed(0)
    wave = torch.sin(torch.arange(64.0) / 2.0)
    x = torch.stack([wave * torch.where(torch.arange(64) < 32, 0.2, 2.0), wave])[None]  # (1, 2, 64)
    norm = M.Norm(2, keep_amplitude=True)
    plain = torch.nn.functional.instance_norm(x)
    assert torch.allclose(norm(x), plain, atol=1e-6)  # keep = tanh(0) = 0
    with torch.no_grad():
        norm.keep.fill_(10.0)  # tanh: keep all of it
    kept = norm(x)
    quiet, loud = kept[0, 0, 8:24].abs().max(), kept[0, 0, 40:56].abs().max()
    plain_ratio = plain[0, 0, 40:56].abs().max() / plain[0, 0, 8:24].abs().max()
    assert loud / quiet > 5 * plain_ratio  # the loud second stays louder than instance norm says
    # calibrating sets each reference to the layer's usual spread, then stops
    g = M.Translator(M.ModelConfig(num_styles=3, keep_amplitude=True))
    M.calibrate_amplitude(
        g, torch.randn(4, Fe.CONTENT_CHANNELS, 32), torch.randn(4, Fe.STYLE3D_CHANNELS, 32)
    )
    refs = [m.log_ref for m in g.modules() if isinstance(m, M.Norm)]
    assert len(refs) == 9 and all(float(r.detach().abs().max()) > 0 for r in refs)
    assert not any(m.calibrating for m in g.modules() if isinstance(m, M.Norm))


def _checkpoint_with_adam_moments(g, cfg, opt, content, style) -> dict:
    """A checkpoint of ``g`` whose optimiser holds Adam moments for every parameter."""
    for _ in range(2):
        opt.zero_grad()
        g(content, style).square().mean().backward()
        opt.step()
    return {"model_config": cfg.to_dict(), "generator": g.state_dict(), "opt_g": opt.state_dict()}


def test_grown_decoder_translates_as_before_then_learns_with_the_old_moments():
    from training.translator import train as T

    torch.manual_seed(0)
    cfg = M.ModelConfig(num_styles=3, keep_amplitude=True, content_channels=[16, 24])
    cfg.style_channels, cfg.style_dim, cfg.mlp_hidden = [16, 16, 16], 8, 12
    g = M.Translator(cfg)
    content = torch.randn(2, Fe.CONTENT_CHANNELS, 32)
    style = torch.randn(2, Fe.STYLE3D_CHANNELS, 32)
    M.calibrate_amplitude(g, content, style)
    names = T._optimizer_names(g, 2)
    params = dict(g.named_parameters())
    opt = torch.optim.Adam([params[n] for n in names[0]], lr=1e-3)
    opt.add_param_group({"params": [params[n] for n in names[1]], "lr_scale": 30.0})
    ckpt = _checkpoint_with_adam_moments(g, cfg, opt, content, style)

    grown = T.grow_decoder(ckpt, 2)
    assert grown["model_config"]["decoder_resblocks"] == cfg.decoder_resblocks + 2
    h = M.Translator(M.ModelConfig(**grown["model_config"]))
    h.load_state_dict(grown["generator"])
    with torch.no_grad():
        assert torch.equal(h(content, style), g(content, style))
    new_names = T._optimizer_names(h, 2)
    new_params = dict(h.named_parameters())
    opt_h = torch.optim.Adam([new_params[n] for n in new_names[0]], lr=1e-3)
    opt_h.add_param_group({"params": [new_params[n] for n in new_names[1]], "lr_scale": 30.0})
    opt_h.load_state_dict(grown["opt_g"])
    old_state = {n: opt.state[params[n]] for n in names[0] + names[1] if params[n] in opt.state}
    assert len(old_state) > 20  # the 2D style encoder, unused here, has none
    for name in old_state:
        moved = opt_h.state[new_params[name]]["exp_avg"]
        if name.startswith("decoder.mlp.4"):  # the new blocks' rows sit between the old ones
            rows = 4 * cfg.content_channels[-1] * cfg.decoder_resblocks
            assert torch.equal(moved[:rows], old_state[name]["exp_avg"][:rows])
            assert torch.equal(moved[-2 * 16 :], old_state[name]["exp_avg"][-2 * 16 :])
            assert not moved[rows : rows + 2 * 4 * 24].any()
        else:
            assert torch.equal(moved, old_state[name]["exp_avg"])
    assert all(new_params[n] not in opt_h.state for n in new_names[0] if ".res.2." in n)
    # the new blocks learn: after a step their second AdaIN scale is no longer zero
    opt_h.zero_grad()
    h(content, style).square().mean().backward()
    opt_h.step()
    with torch.no_grad():
        p = h.decoder.mlp(h.style3d(style)).split(h.decoder.param_sizes, dim=1)[2]
        assert float((1.0 + p.split(24, dim=1)[2]).abs().max()) > 0


def test_narrowed_content_code_starts_as_its_principal_projection():
    from types import SimpleNamespace

    from training.translator import train as T

    torch.manual_seed(0)
    cfg = M.ModelConfig(num_styles=3, content_channels=[16, 24])
    cfg.style_channels, cfg.style_dim, cfg.mlp_hidden = [16, 16, 16], 8, 12
    g = M.Translator(cfg)
    opt = torch.optim.Adam(g.parameters(), lr=1e-3)
    content, style = (
        torch.randn(2, Fe.CONTENT_CHANNELS, 32),
        torch.randn(2, Fe.STYLE3D_CHANNELS, 32),
    )
    opt.zero_grad()
    g(content, style).square().mean().backward()
    opt.step()
    ckpt = {"model_config": cfg.to_dict(), "generator": g.state_dict(), "opt_g": opt.state_dict()}
    rng = np.random.default_rng(0)
    kinds = {"content": Fe.CONTENT_CHANNELS, "style3d": Fe.STYLE3D_CHANNELS, "style2d": 32}
    stats = Fe.FeatureStats(
        {k: rng.normal(size=c).astype(np.float32) for k, c in kinds.items()},
        {k: rng.uniform(0.5, 2, size=c).astype(np.float32) for k, c in kinds.items()},
    )
    clips = [SimpleNamespace(content=rng.normal(size=(f, Fe.CONTENT_CHANNELS))) for f in (40, 64)]
    prep = SimpleNamespace(stats=stats, train=clips)
    g.eval()
    windows = [c.content[s : s + 16].T for c in clips for s in range(0, len(c.content) - 15, 8)]
    x = (
        torch.tensor(np.stack(windows), dtype=torch.float32)
        - torch.tensor(stats.mean["content"])[:, None]
    ) / torch.tensor(stats.std["content"])[:, None]
    with torch.no_grad():
        z = g.content_encoder(x)
    flat = z.transpose(1, 2).reshape(-1, 24).double().numpy()
    mean = flat.mean(0)
    basis = np.linalg.svd(flat - mean, full_matrices=False)[2][:6]
    expected = (flat - mean) @ basis.T @ basis + mean

    narrowed = T.narrow_content(ckpt, 6, prep, window=16)
    h = M.Translator(M.ModelConfig(**narrowed["model_config"])).eval()
    h.load_state_dict(narrowed["generator"])
    with torch.no_grad():
        code = h.content_encoder(x).transpose(1, 2).reshape(-1, 24).double().numpy()
    np.testing.assert_allclose(code, expected, atol=1e-4)
    assert np.abs(code - flat).max() > 1e-2  # six of 24 channels lose something
    # the decoder and everything else keep their weights and Adam moments
    for name, value in g.state_dict().items():
        assert torch.equal(narrowed["generator"][name], value)
    moved = torch.optim.Adam(h.parameters(), lr=1e-3)
    moved.load_state_dict(narrowed["opt_g"])
    old = dict(g.named_parameters())
    for name, p in h.named_parameters():
        if "bottleneck" in name:
            assert p not in moved.state
        elif old[name] in opt.state:  # the 2D style encoder, unused here, has none
            assert torch.equal(moved.state[p]["exp_avg"], opt.state[old[name]]["exp_avg"])
    assert len(moved.state) == len(opt.state) > 20
    for width in (0, 25):
        with pytest.raises(SystemExit, match="the content code has 24 channels"):
            T.narrow_content(ckpt, width, prep, window=16)
    with pytest.raises(ValueError, match="content_bottleneck 25"):
        M.ModelConfig(content_bottleneck=25, content_channels=[16, 24])
    # at full width the bottleneck changes nothing
    full = T.narrow_content(ckpt, 24, prep, window=16)
    f = M.Translator(M.ModelConfig(**full["model_config"])).eval()
    f.load_state_dict(full["generator"])
    with torch.no_grad():
        torch.testing.assert_close(f.content_encoder(x), z, atol=1e-4, rtol=1e-4)


def test_mixed_kernels_start_as_the_old_decoder_then_part():
    from training.translator import train as T

    torch.manual_seed(0)
    cfg = M.ModelConfig(num_styles=3, content_channels=[16, 24])
    cfg.style_channels, cfg.style_dim, cfg.mlp_hidden = [16, 16, 16], 8, 12
    g = M.Translator(cfg)
    content = torch.randn(3, Fe.CONTENT_CHANNELS, 32)
    style = torch.randn(3, Fe.STYLE3D_CHANNELS, 32)
    opt = torch.optim.Adam(g.parameters(), lr=1e-3)
    ckpt = _checkpoint_with_adam_moments(g, cfg, opt, content, style)

    mixed = T.mix_kernels(ckpt, 3)
    h = M.Translator(M.ModelConfig(**mixed["model_config"]))
    h.load_state_dict(mixed["generator"])
    with torch.no_grad():
        torch.testing.assert_close(h(content, style), g(content, style), atol=1e-5, rtol=1e-5)
    kernels = h.decoder.res[0].conv1.weight.detach().unflatten(0, (3, 24))
    old = g.decoder.res[0].conv1.weight.detach()
    assert not torch.equal(kernels[0], kernels[1])  # perturbed apart...
    torch.testing.assert_close(kernels.mean(0), old, atol=1e-6, rtol=1e-6)  # ...about the old one
    params = dict(h.named_parameters())
    opt_h = torch.optim.Adam(params.values(), lr=1e-3)
    opt_h.load_state_dict(mixed["opt_g"])
    moments = opt_h.state[params["decoder.res.0.conv1.weight"]]["exp_avg_sq"]
    old_moments = opt.state[dict(g.named_parameters())["decoder.res.0.conv1.weight"]]
    assert torch.equal(moments.unflatten(0, (3, 24))[2], old_moments["exp_avg_sq"])
    assert params["decoder.mix.weight"] not in opt_h.state
    # after a step the clips no longer mix evenly, and differently from each other
    opt_h.zero_grad()
    h(content, style).square().mean().backward()
    opt_h.step()
    with torch.no_grad():
        logits = h.decoder.mix(h.style3d(style))
    assert float(logits.std(dim=0).max()) > 0
    with pytest.raises(SystemExit, match="already mixes"):
        T.mix_kernels(mixed, 2)
    with pytest.raises(ValueError, match="style_kernels 1"):
        M.ModelConfig(style_kernels=1)


def random_batch(batch: int, frames: int, styles: list[int]):
    from training.translator import train as T

    return T.Batch(
        content=torch.randn(batch, Fe.CONTENT_CHANNELS, frames),
        style3d=torch.randn(batch, Fe.STYLE3D_CHANNELS, frames),
        style2d=torch.randn(batch, Fe.STYLE2D_CHANNELS, frames),
        style=torch.tensor(styles),
        positions=torch.randn(batch, frames, 21, 3),
        hips_height=torch.ones(batch, frames),
    )


def identity_stats() -> Fe.FeatureStats:
    """Statistics that leave standardised features as they are."""
    kinds = {
        "content": Fe.CONTENT_CHANNELS,
        "style3d": Fe.STYLE3D_CHANNELS,
        "style2d": Fe.STYLE2D_CHANNELS,
    }
    return Fe.FeatureStats(
        {k: np.zeros(c, np.float32) for k, c in kinds.items()},
        {k: np.ones(c, np.float32) for k, c in kinds.items()},
    )


def tiny_networks(**config) -> tuple[M.Translator, M.Discriminator, Fe.FeatureStats]:
    """A generator and a discriminator of three styles (``config`` adds to their
    ``ModelConfig``), seeded and in eval mode, and identity feature statistics."""
    torch.manual_seed(0)
    cfg = M.ModelConfig(num_styles=3, **config)
    return M.Translator(cfg).eval(), M.Discriminator(cfg).eval(), identity_stats()


def test_content_cycle_translates_to_its_own_style_batch():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x, r = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2], [2, 0]))
    off = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_cycle=0.0))
    on = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_cycle=1.0))
    with torch.no_grad():
        torch.manual_seed(1)
        _, logs_off, *_ = off.generator(m, n, x)
        torch.manual_seed(1)
        _, logs_x, *_ = on.generator(m, n, x)
        torch.manual_seed(1)
        _, logs_r, *_ = on.generator(m, n, x, r=r)
    assert logs_off["content_cycle"] == 0.0 and logs_x["content_cycle"] > 0.0
    # r's style feeds the cycle only: the adversarial term still judges the translation to x
    assert logs_r["content_cycle"] != pytest.approx(logs_x["content_cycle"])
    assert logs_r["adv_g"] == pytest.approx(logs_x["adv_g"])


def test_hands_dropped_measures_raised_hands_that_end_below_the_head():
    from training.translator import train as T

    hand, head = C.INDEX["Hand_L"] - 1, C.INDEX["Head"] - 1  # body joints: no joint_Root
    content = torch.zeros(1, 4, 21, 3)
    content[..., head, 1] = 1.6
    content[..., hand, 1] = torch.tensor([1.0, 1.9, 2.0, 1.0])  # raised in frames 1 and 2
    translation = content.clone()
    assert T.hands_dropped(content, translation) == 0.0
    translation[..., hand, 1] = torch.tensor([0.2, 1.2, 1.7, 0.2])  # 0.4 below, then above
    assert T.hands_dropped(content, translation) == pytest.approx(0.2)  # (0.4 + 0) / 2
    translation[..., hand, 1] = 0.0  # lowering a hand the content never raised costs nothing
    assert T.hands_dropped(content[..., [0, 3], :, :], translation[..., [0, 3], :, :]) == 0.0


def test_hands_lifted_measures_lowered_hands_that_end_above_the_head():
    from training.translator import train as T

    hand, head = C.INDEX["Hand_R"] - 1, C.INDEX["Head"] - 1
    content = torch.zeros(1, 4, 21, 3)  # every other hand sits at 0, well below the head
    content[..., head, 1] = 1.6
    content[..., hand, 1] = torch.tensor([0.5, 1.55, 1.9, 0.5])  # near the face, then raised
    translation = content.clone()
    assert T.hands_lifted(content, translation) == 0.0
    translation[..., hand, 1] = torch.tensor([1.8, 1.8, 1.8, 1.6])  # lifted in frame 0 only
    # frames 0 and 3 count for this hand (frame 1 is within 10 cm of the head): 0.2 and 0;
    # the other hand's 4 lowered frames stay at 0
    assert T.hands_lifted(content, translation) == pytest.approx(0.2 / 6)
    assert T.hands_lifted(translation, content) == 0.0  # the converse is hands_dropped's


def test_hand_amplitude_changed_allows_a_factor_of_two_either_way_by_default():
    from training.translator import train as T

    default = T.TrainConfig().hand_amplitude_ratio
    left, right = C.INDEX["Hand_L"] - 1, C.INDEX["Hand_R"] - 1
    content = torch.zeros(1, 32, 21, 3)
    wave = torch.sin(torch.linspace(0, 2 * math.pi, 32))
    content[..., left, 1] = 0.3 * wave  # the left hand moves, the right is still
    assert T.hand_amplitude_changed(content, content, default) == 0.0
    translation = content.clone()
    translation[..., left, 1] *= 0.6  # smaller, within a factor of two
    translation[..., right, 0] = 0.01 * wave  # the idle hand trembles under the floor
    assert T.hand_amplitude_changed(content, translation, default) == 0.0
    assert T.hand_amplitude_changed(content, translation, ratio=1.25) > 0.0  # a tighter band
    translation[..., left, 1] = 0.3 * wave / 4  # a quarter: beyond the factor, on one hand
    a, floor = 0.3 * float(wave.std(unbiased=False)), 2.0 / Fe.LEG
    beyond = math.log((a + floor) / (a / 4 + floor)) - math.log(2.0)
    assert T.hand_amplitude_changed(content, translation, default) == pytest.approx(
        beyond / 2, rel=1e-4
    )
    translation = content.clone()
    translation[..., right, 0] = 0.2 * wave  # the idle hand swings
    assert T.hand_amplitude_changed(content, translation, default) > 0.5


def test_hand_speed_changed_tells_a_held_raise_from_a_wave():
    from training.translator import train as T

    ratio = T.TrainConfig().hand_speed_ratio
    left = C.INDEX["Hand_L"] - 1
    t = torch.linspace(0, 1, 32)
    raise_ = torch.zeros(1, 32, 21, 3)
    raise_[..., left, 1] = 0.5 * (t / 0.3).clamp(max=1.0)  # up in 0.3 s, then held
    wave = raise_.clone()
    wave[..., left, 0] = 0.15 * torch.sin(2 * math.pi * 2.5 * t)  # and swung side to side
    assert T.hand_speed_changed(raise_, raise_, ratio) == 0.0
    slower = raise_.clone()
    slower[..., left, 1] = 0.5 * (t / 0.4).clamp(max=1.0)  # up in 0.4 s: a style's pace
    assert T.hand_speed_changed(raise_, slower, ratio) == 0.0
    assert T.hand_speed_changed(raise_, wave, ratio) > 0.1  # a raise turned into a wave
    assert T.hand_speed_changed(wave, raise_, ratio) > 0.1  # and back
    # the amplitude term alone barely tells them apart
    assert T.hand_amplitude_changed(raise_, wave, T.TrainConfig().hand_amplitude_ratio) == 0.0


def test_raised_hands_term_is_logged_only_when_weighted():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x, r = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2], [2, 0]))
    m.positions[..., C.INDEX["Hand_L"] - 1, 1] = 50.0  # the content's left hand, far above

    def generate(**weights):
        """The generator loss with these weights, the same random draws each time."""
        losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(**weights))
        with torch.no_grad():
            torch.manual_seed(1)
            return losses.generator(m, n, x, r=r)

    total_off, logs_off, *_ = generate()
    total_on, logs_on, *_ = generate(w_raised_hands=1.0)
    assert logs_off["raised_hands_cm"] == 0.0 and logs_on["raised_hands_cm"] > 0.0
    expected = logs_on["raised_hands_cm"] / Fe.LEG
    assert float(total_on - total_off) == pytest.approx(expected, rel=1e-4, abs=1e-6)
    # the hand-amplitude term judges the translations to x and to r alike
    total_amp, logs_amp, fake_in, _ = generate(w_hand_amplitude=1.0)
    fake = fake_in[:, Fe.STYLE3D_CHANNELS :]  # the discriminator's input: positions, output
    with torch.no_grad():
        fake_pos = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig()).positions(
            fake, m.hips_height
        )
    assert logs_off["hand_amplitude"] == 0.0 and logs_amp["hand_amplitude"] > 0.0
    assert logs_amp["hand_amplitude"] == pytest.approx(
        float(
            T.hand_amplitude_changed(m.positions, fake_pos, T.TrainConfig().hand_amplitude_ratio)
        ),
        rel=1e-5,
    )  # no w_cycle or w_raised_hands: no translation to r is made
    assert float(total_amp - total_off) == pytest.approx(logs_amp["hand_amplitude"], rel=1e-4)
    # the foot-pitch term likewise, on a content whose feet take turns on the floor
    m.positions[:, :, T._FEET, 1] = stepping_feet()[0, :, T._FEET, 1]
    total_off, logs_off, *_ = generate()
    total_feet, logs_feet, *_ = generate(w_foot_pitch=1.0)
    want = float(T.feet_pitched(m.positions, fake_pos))
    assert logs_off["foot_pitch_cm"] == 0.0 and want > 0.0
    assert logs_feet["foot_pitch_cm"] == pytest.approx(want * Fe.LEG, rel=1e-5)
    assert float(total_feet - total_off) == pytest.approx(want, rel=1e-4)


def test_reconstruction_velocity_term_compares_joint_velocities_when_weighted():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2]))

    def generate(**weights):
        losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(**weights))
        with torch.no_grad():
            torch.manual_seed(1)
            return losses, losses.generator(m, n, x)

    _, (total_off, logs_off, *_) = generate()
    losses, (total_on, logs_on, *_) = generate(w_rec_vel=2.0)
    with torch.no_grad():
        torch.manual_seed(1)
        use2d = torch.rand(2) < losses.cfg.p_style2d
        rec = g.decoder(g.content_encoder(m.content), losses.style_codes(n, use2d)[1])
        pos = losses.positions(rec, m.hips_height)
    want = float((pos.diff(dim=1) - m.positions.diff(dim=1)).abs().mean())
    assert logs_off["rec_vel_cm_s"] == 0.0 and want > 0.0
    assert logs_on["rec_vel_cm_s"] == pytest.approx(want * Fe.LEG * C.FPS, rel=1e-4)
    assert float(total_on - total_off) == pytest.approx(2.0 * want, rel=1e-4)
    # a content standing still: the term is the reconstruction's own speed
    still = m.positions[:, :1].expand_as(m.positions).clone()
    m.positions = still
    _, (_, logs_still, *_) = generate(w_rec_vel=1.0)
    assert logs_still["rec_vel_cm_s"] == pytest.approx(
        float(pos.diff(dim=1).abs().mean()) * Fe.LEG * C.FPS, rel=1e-4
    )


def test_extra_windows_add_their_own_reconstruction_under_the_reconstruction_weights():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2]))
    e = random_batch(3, 32, [-1, -1, -1])  # unlabelled: no style index
    weights = {"w_rec_rot": 0.5, "w_rec_pos": 4.0, "w_rec_vel": 3.0}
    losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(**weights))

    def generate(extra):
        with torch.no_grad():
            torch.manual_seed(1)
            return losses.generator(m, n, x, e=extra)

    total_off, logs_off, *_ = generate(None)
    total_on, logs_on, *_ = generate(e)
    with torch.no_grad():  # e decoded from its own content code with its own 3D style code
        rec = g.decoder(g.content_encoder(e.content), g.style3d(e.style3d))
        pos = losses.positions(rec, e.hips_height)
    rot_l1 = float((rec - e.rotations).abs().mean())
    pos_l1 = float((pos - e.positions).abs().mean())
    vel_l1 = float((pos.diff(dim=1) - e.positions.diff(dim=1)).abs().mean())
    assert logs_off["extra_rec_pos_cm"] == 0.0
    assert logs_on["extra_rec_pos_cm"] == pytest.approx(pos_l1 * Fe.LEG, rel=1e-5)
    want = 0.5 * rot_l1 + 4.0 * pos_l1 + 3.0 * vel_l1
    assert float(total_on - total_off) == pytest.approx(want, rel=1e-4)
    # the labelled windows' own terms are untouched
    for key in ("rec_pos_cm", "rec_vel_cm_s", "adv_g"):
        assert logs_on[key] == logs_off[key]


def test_random_windows_fit_their_clips_and_favour_long_ones():
    def clip(frames: int, take: str) -> TD.EncodedClip:
        return TD.EncodedClip(
            content=np.zeros((frames, Fe.CONTENT_CHANNELS), np.float32),
            style3d=np.zeros((frames, Fe.STYLE3D_CHANNELS), np.float32),
            style2d=np.zeros((1, frames, Fe.STYLE2D_CHANNELS), np.float32),
            style=-1,
            take=take,
        )

    clips = [clip(20, "short"), clip(63, "long"), clip(32 + 9, "mid")]  # 0, 32 and 10 windows
    items = TD.random_windows(clips, 32, 4200, np.random.default_rng(0))
    assert all(0 <= s <= c.num_frames - 32 for c, s in items)
    counts = {take: sum(c.take == take for c, _ in items) for take in ("short", "long", "mid")}
    assert counts["short"] == 0
    assert counts["long"] / counts["mid"] == pytest.approx(3.2, rel=0.15)
    starts = {s for c, s in items if c.take == "long"}
    assert starts == set(range(32))  # every start of the long clip drawn
    windows = TD.cut(items[:5], 32)
    assert windows.content.shape == (5, 32, Fe.CONTENT_CHANNELS)


def test_smoke_training_with_unlabelled_motion():
    data_path("bandai", "dataset-1")
    for folder in ("cmu-31", "xia", "cmu-dance-43", "dance-with-melody"):
        data_path(folder)
    from training.translator import train as T

    cfg = T.TrainConfig(clips_per_style=2, val_fraction=0.5, views=1, extra_batch=4)
    prep = T.prepare(cfg)
    from training import data as D

    long_enough = {c.take for c in D.load_unlabelled_motion() if c.num_frames >= cfg.window}
    assert {c.take for c in prep.extra} == long_enough and len(long_enough) >= 45
    assert {c.style for c in prep.extra} == {-1} and all(c.label is None for c in prep.extra)
    assert not {c.take for c in prep.extra} & {c.take for c in prep.train + prep.val}
    # the statistics are the Bandai training clips' alone
    assert np.allclose(
        prep.stats.mean["content"],
        np.concatenate([c.content for c in prep.train]).mean(0),
        atol=1e-4,
    )


def stepping_feet(frames: int = 32) -> torch.Tensor:
    """Root-local positions ``(1, frames, 21, 3)``: a body 1 leg length up whose feet take
    turns, each foot joint at its ground level (ankle 0.08, toes 0.02) when planted and
    0.15 higher when not."""
    from training.translator import train as T

    pos = torch.linspace(-0.5, 0.5, 21 * 3).reshape(1, 1, 21, 3).repeat(1, frames, 1, 1)
    pos[..., 1] += 1.0
    left_up = (torch.arange(frames) // 8) % 2 == 1
    for k, j in enumerate(T._FEET):  # Foot_L, Toes_L, Foot_R, Toes_R
        up = left_up if k < 2 else ~left_up
        pos[0, :, j, 1] = (0.08 if k % 2 == 0 else 0.02) + 0.15 * up
    return pos


@pytest.mark.parametrize("sink", [-0.12, 0.07])
def test_ground_translation_stands_a_sunk_or_floating_body_on_the_contents_floor(sink):
    from training.translator import train as T

    content = stepping_feet()
    translation = content.clone()
    translation[..., 1] += sink
    translation.requires_grad_()
    grounded = T.ground_translation(content, translation, 15.0)
    assert torch.allclose(grounded, content, atol=1e-5)  # only the height moved, back
    grounded.sum().backward()  # the shift follows the translation's feet: no detach
    assert torch.isfinite(translation.grad).all()


def test_ground_translation_leaves_out_a_foot_held_up_all_window():
    from training.translator import train as T

    content = stepping_feet()
    content[0, :, T._FEET[:2], 1] += 0.5  # the left foot never comes down
    content[0, :, T._FEET[2:], 1] = torch.tensor([0.08, 0.02])  # the right stays planted
    translation = content.clone()
    translation[0, :, T._FEET[:2], 1] = -0.3  # the held-up foot dips: not a ground contact
    assert torch.equal(T.ground_translation(content, translation, 15.0), translation)
    translation[..., 1] -= 0.1  # the planted foot sinks with the body: lifted back
    expected = translation.clone()
    expected[..., 1] += 0.1
    assert torch.allclose(T.ground_translation(content, translation, 15.0), expected, atol=1e-5)


def test_translations_are_grounded_for_the_discriminator_only_when_asked():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2]))
    m.positions[:] = stepping_feet().repeat(2, 1, 1, 1)
    runs = {}
    for ground in (False, True):
        losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(ground_translations=ground))
        with torch.no_grad():
            torch.manual_seed(1)
            runs[ground] = losses.generator(m, n, x)
    fake_in = runs[False][2]
    fake = fake_in[:, Fe.STYLE3D_CHANNELS :]
    plain = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig()).positions(fake, m.hips_height)
    grounded = T.ground_translation(m.positions, plain, 15.0)
    assert not torch.allclose(grounded, plain, atol=1e-3)  # a random decoder floats or sinks
    flat = grounded.reshape(grounded.shape[:2] + (-1,)).transpose(1, 2)
    stand = T.Standardizer(stats).style3d.standardize(flat)
    assert torch.allclose(runs[True][2][:, : Fe.STYLE3D_CHANNELS], stand, atol=1e-5)
    assert torch.equal(runs[True][2][:, Fe.STYLE3D_CHANNELS :], fake)  # rotations untouched
    # reconstruction is still judged at the content's own hips height
    assert runs[True][1]["rec_pos_cm"] == runs[False][1]["rec_pos_cm"]


def test_content_heads_judge_translations_by_the_content_windows_label():
    from training.translator import train as T

    g, d, stats = tiny_networks(num_contents=4)
    scores, _ = d(torch.randn(2, Fe.STYLE3D_CHANNELS + Fe.OUTPUT_CHANNELS, 32))
    assert scores.shape[1] == 3 + 4  # style heads, then content heads
    m, n, x = (random_batch(3, 32, s) for s in ([0, 1, 2], [0, 1, 2], [1, 2, 0]))
    m.label, x.label = torch.tensor([2, -1, 0]), torch.tensor([2, 1, 0])  # m's second: none
    on = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_content_adv=1.0))
    with torch.no_grad():
        torch.manual_seed(1)
        total, logs, fake_in, wild_in = on.generator(m, n, x)
        fake = fake_in[:, Fe.STYLE3D_CHANNELS :]  # the discriminator's input: positions, output
        assert torch.equal(on.disc_input(fake, on.positions(fake, m.hips_height)), fake_in)
        fake_scores = d(fake_in)[0]
    expected = -0.5 * float(fake_scores[0, 3 + 2].mean() + fake_scores[2, 3 + 0].mean())
    assert logs["content_adv_g"] == pytest.approx(expected, rel=1e-4)
    off = T.Losses(g, M.Discriminator(M.ModelConfig(num_styles=3)), T.Standardizer(stats),
                   T.TrainConfig())  # fmt: skip
    with torch.no_grad():
        assert off.generator(m, n, x)[1]["content_adv_g"] == 0.0
    # the discriminator learns its content heads from real windows and translations
    loss, logs_d = on.discriminator(m, x, fake_in, r1=True)
    loss.backward()
    assert logs_d["d_real_content"] > 0.0 and logs_d["d_fake_content"] > 0.0
    assert float(d.content_head.weight.grad.abs().sum()) > 0.0
    assert wild_in is None  # no term translates to another style r here
    # translations to r, scored by the content heads in the generator's loss, are fakes to
    # the heads too
    r = random_batch(3, 32, [2, 0, 1])
    both = T.Losses(g, d, T.Standardizer(stats),
                    T.TrainConfig(w_content_adv=1.0, w_raised_hands=1.0, pair_content=True))  # fmt: skip
    with torch.no_grad():
        torch.manual_seed(2)
        _, _, fake_in, wild_in = both.generator(m, n, x, r=r)
        wild = wild_in[:, Fe.STYLE3D_CHANNELS :]
        assert torch.equal(both.disc_input(wild, both.positions(wild, m.hips_height)), wild_in)
        wild_scores, fake_scores = d(wild_in)[0], d(fake_in)[0]
        _, logs_both = both.discriminator(m, x, fake_in, False, wild_in)
    hinge = lambda sc: torch.cat([sc[0, 3 + 2], sc[2, 3 + 0]]).add(1).relu().mean()  # noqa: E731
    expected = 0.5 * float(hinge(fake_scores) + hinge(wild_scores))
    assert not torch.equal(wild_in, fake_in)
    assert logs_both["d_fake_content"] == pytest.approx(expected, rel=1e-4)


def test_style_heads_classify_reals_and_translations_only_when_weighted():
    from training.translator import train as T

    g, d, stats = tiny_networks(num_contents=2)
    m, n, x = (random_batch(3, 32, s) for s in ([0, 1, 2], [0, 1, 2], [1, 2, 0]))
    off = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig())
    on = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_style_cls=0.5))
    with torch.no_grad():
        torch.manual_seed(1)
        total_off, logs_off, *_ = off.generator(m, n, x)
        torch.manual_seed(1)
        total_on, logs_on, fake_in, _ = on.generator(m, n, x)
        # the logits are the style heads' scores only (not the content heads'), over time
        logits = d(fake_in)[0][:, :3].mean(dim=-1)
    expected = float(torch.nn.functional.cross_entropy(logits, x.style))
    assert logs_off["style_cls_g"] == 0.0
    assert logs_on["style_cls_g"] == pytest.approx(expected, rel=1e-5)
    assert float(total_on - total_off) == pytest.approx(0.5 * expected, rel=1e-4)
    # the discriminator learns the classifier from real windows, not from translations
    _, logs_plain = off.discriminator(m, x, fake_in, r1=False)
    assert "d_style_cls" not in logs_plain
    loss, logs_d = on.discriminator(m, x, fake_in, r1=False)
    with torch.no_grad():
        real_x, real_m = d(x.disc_input)[0][:, :3].mean(-1), d(m.disc_input)[0][:, :3].mean(-1)
    ce = torch.nn.functional.cross_entropy
    expected_d = 0.5 * float(ce(real_x, x.style) + ce(real_m, m.style))
    assert logs_d["d_style_cls"] == pytest.approx(expected_d, rel=1e-5)
    plain, _ = off.discriminator(m, x, fake_in, r1=False)
    assert float((loss - plain).detach()) == pytest.approx(0.5 * expected_d, rel=1e-4)
    assert 0.0 <= logs_d["d_style_acc_real"] <= 1.0 and 0.0 <= logs_d["d_style_acc_fake"] <= 1.0


def test_content_style_probe_learns_style_and_the_encoder_answers_the_content_prior():
    from training.translator import train as T

    torch.manual_seed(0)
    cfg = M.ModelConfig(num_styles=3)
    g, d = M.Translator(cfg), M.Discriminator(cfg)
    m, n, x = (random_batch(3, 32, s) for s in ([0, 1, 2], [0, 1, 2], [1, 2, 0]))
    m.label = torch.tensor([0, 1, -1])  # the last window has no content label
    probe = torch.nn.Linear(2 * cfg.content_channels[-1], 3)
    prior = torch.tensor([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]])
    stats = T.Standardizer(identity_stats())
    on = T.Losses(g, d, stats, T.TrainConfig(w_content_style=2.0), probe, prior)
    off = T.Losses(g, d, stats, T.TrainConfig())
    torch.manual_seed(1)
    total, logs, *_ = on.generator(m, n, x)
    torch.manual_seed(1)
    total_off, logs_off, *_ = off.generator(m, n, x)
    with torch.no_grad():
        z = g.content_encoder(m.content)
        logits = probe(torch.cat([z.mean(-1), z.std(-1)], dim=1))
        logp = torch.log_softmax(logits[:2], dim=1)
        kl = (
            sum(
                float((p[p > 0] * (p[p > 0].log() - lp[p > 0])).sum())
                for p, lp in zip(prior, logp, strict=True)
            )
            / 2
        )
        ce = float(torch.nn.functional.cross_entropy(logits, m.style))
    assert logs_off["content_style_kl"] == 0.0 and logs_off["probe_ce"] == 0.0
    assert logs["content_style_kl"] == pytest.approx(kl, rel=1e-4)
    assert logs["probe_ce"] == pytest.approx(ce, rel=1e-4)
    # the probe's loss is added to the total but leaves the logged generator total alone
    assert float(total.detach()) == pytest.approx(logs["total_g"] + ce, rel=1e-4)
    assert logs["total_g"] - logs_off["total_g"] == pytest.approx(2.0 * kl, rel=1e-3)
    total.backward()
    # the encoder gets the KL's gradient, the probe the cross-entropy's only
    assert g.content_encoder.first.weight.grad.abs().sum() > 0
    probe_grad = probe.weight.grad.clone()
    probe.zero_grad()
    summary = torch.cat([z.mean(-1), z.std(-1)], dim=1)
    torch.nn.functional.cross_entropy(probe(summary), m.style).backward()
    assert torch.allclose(probe_grad, probe.weight.grad, atol=1e-6)


def test_style_prior_spreads_each_label_over_the_styles_that_perform_it():
    from training.translator import train as T
    from training.translator.data import EncodedClip

    def clip(style: int, label: str | None, frames: int) -> EncodedClip:
        z = np.zeros((frames, 1), np.float32)
        return EncodedClip(z, z, z[None], style, f"take{style}{label}", label)

    train = [clip(0, "walk", 100), clip(0, "run", 300), clip(1, "walk", 50), clip(2, None, 10)]
    prep = T.Prepared(["a", "b", "c"], ["run", "walk", "wave"], train, [], [], identity_stats())
    prior = T.style_prior(prep, {"run": 0, "walk": 1, "wave": 2})
    # walk: a quarter of style a's frames, all of style b's
    assert prior[1].tolist() == pytest.approx([0.2, 0.8, 0.0])
    assert prior[0].tolist() == pytest.approx([1.0, 0.0, 0.0])
    assert prior[2].tolist() == pytest.approx([1 / 3] * 3)  # nobody performs it


def test_mirror_adds_each_training_clip_the_other_way_round_and_leaves_validation():
    data_path("bandai", "dataset-1")
    from training.translator import train as T

    cfg = T.TrainConfig(clips_per_style=3, val_fraction=0.34, views=1)
    plain = T.prepare(cfg)
    both = T.prepare(dataclasses.replace(cfg, mirror=True))
    assert both.val_takes == plain.val_takes
    assert [c.take for c in both.val] == [c.take for c in plain.val]
    assert len(both.train) == 2 * len(plain.train)
    mirrors = both.train[len(plain.train) :]
    assert all(m.take == f"{c.take}~mirrored" for c, m in zip(plain.train, mirrors, strict=True))
    assert [m.style for m in mirrors] == [c.style for c in plain.train]
    assert set(both.contents) == set(plain.contents) | {
        TD.MIRRORED_CONTENT.get(label, label) for label in plain.contents
    }
    # left and right swapped: the lateral channels' means cancel
    lateral = slice(0, None, 3)  # x of each root-local joint position
    mean_x = np.concatenate([c.style3d for c in both.train])[:, lateral].mean(axis=0)
    plain_x = np.concatenate([c.style3d for c in plain.train])[:, lateral].mean(axis=0)
    middle = [i for i, j in enumerate(C.MIRROR_INDEX[1:]) if j == i + 1]
    assert np.abs(mean_x[middle]).max() < 1e-3 < np.abs(plain_x[middle]).max()


def test_feet_pitched_compares_flat_planted_feet_only():
    from training.translator import train as T

    content = stepping_feet()  # planted: ankle 0.08, toes 0.02 (rise -0.06); up: both +0.15
    translation = content.clone()
    translation[..., 1] += 0.3  # a vertical shift changes no pitch
    assert float(T.feet_pitched(content, translation)) == pytest.approx(0.0, abs=1e-6)
    toe_l, toe_r = T._FEET[1], T._FEET[3]
    left_up = (torch.arange(32) // 8) % 2 == 1
    translation[0, :, toe_l, 1] -= 0.04  # the left toe pitched down, planted or not
    translation[0, ~left_up, toe_r, 1] -= 1.0  # the right toe while its foot is in the air
    # the left foot is planted in 16 of 32 frames, the right in the other 16: errors of
    # 0.04 over the left's 16 planted frames, averaged with the right's 16 at 0
    assert float(T.feet_pitched(content, translation)) == pytest.approx(0.02, abs=1e-6)
    translation.requires_grad_()
    T.feet_pitched(content, translation).backward()
    assert translation.grad[0, :, toe_l, 1].abs().sum() > 0
    held_up = content.clone()
    held_up[0, :, T._FEET[:2], 1] += 0.5  # the left foot never comes down: never compared
    assert float(T.feet_pitched(held_up, translation.detach())) == pytest.approx(0.0, abs=1e-6)


def moving_clip(phase: np.ndarray, style: int, label: str | None) -> TD.EncodedClip:
    """A clip whose body joints trace a curve ``phase`` (frames,) sets the point on:
    each joint at its own offset from the hips, swept by a different function of the phase."""
    frames = len(phase)
    offsets = np.linspace(-1.0, 1.0, 21 * 3).reshape(21, 3)
    pos = np.zeros((frames, 21, 3), np.float32)
    pos[:, 1:] = offsets[1:] * (
        1.0 + np.sin(phase[:, None, None] * (1 + np.arange(20)[:, None] / 7))
    )
    pos[:, :, 1] += 1.0  # the hips (joint 0) at a height, the body around them
    return TD.EncodedClip(
        content=np.zeros((frames, Fe.CONTENT_CHANNELS), np.float32),
        style3d=pos.reshape(frames, -1),
        style2d=np.zeros((1, frames, Fe.STYLE2D_CHANNELS), np.float32),
        style=style,
        take=f"take-{style}-{frames}",
        label=label,
    )


def test_aligned_frames_undo_a_change_of_timing():
    # b performs the action at an even pace, a lingers over its first half, then hurries
    b_phase = np.linspace(0.0, 3.0, 90)
    t = np.linspace(0.0, 1.0, 120)
    a_time = (t + t**2) / 2
    a = moving_clip(3.0 * a_time, 0, "wave")
    b = moving_clip(b_phase, 1, "wave")
    frames = TD.aligned_frames(a, b)
    truth = np.interp(3.0 * a_time, b_phase, np.arange(90))
    assert frames.shape == (120,) and frames[0] == 0 and frames[-1] == 89
    assert np.all(np.diff(frames) >= 0)
    assert np.abs(frames - truth).max() <= 1.5
    # an even stretch would miss by far more
    assert np.abs(np.linspace(0, 89, 120) - truth).max() > 8


def test_paired_targets_are_the_other_styles_clip_at_the_aligned_frames():
    a = moving_clip(np.linspace(0.0, 3.0, 60), 0, "wave")
    b = moving_clip(np.linspace(0.0, 3.0, 45), 1, "wave")
    same_style = moving_clip(np.linspace(0.0, 3.0, 50), 0, "wave")
    other_label = moving_clip(np.linspace(0.0, 3.0, 50), 2, "bow")
    alignments = TD.Alignments()
    items_m = [(a, 10)] * 3
    items_x = [(b, 5), (same_style, 0), (other_label, 0)]
    target, paired = alignments.targets(items_m, items_x, 32)
    assert paired.tolist() == [True, False, False]
    frames = TD.aligned_frames(a, b)[10:42]
    assert np.array_equal(target[0], b.style3d[frames].reshape(32, 21, 3))
    assert not target[1:].any()
    assert alignments(a, b) is alignments(a, b)  # computed once


def disc_positions(disc_input: torch.Tensor) -> torch.Tensor:
    """``(B, T, 21, 3)`` joint positions of a discriminator input ``(B, C, T)``."""
    b, _, t = disc_input.shape
    return disc_input[:, : Fe.STYLE3D_CHANNELS].transpose(1, 2).reshape(b, t, 21, 3)


def test_paired_term_compares_the_translation_with_its_target_relative_to_the_hips():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2]))
    losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_paired=3.0))
    target = torch.randn(2, 32, 21, 3)

    def generate(paired):
        with torch.no_grad():
            torch.manual_seed(1)
            return losses.generator(m, n, x, paired=paired)

    total_off, logs_off, fake_in, _ = generate(None)
    total_on, logs_on, *_ = generate((target, torch.tensor([True, False])))
    pos = disc_positions(fake_in)
    want = float(T.hips_relative_l1(pos[:1], target[:1]))
    assert logs_off["paired_cm"] == 0.0 and want > 0.0
    assert logs_on["paired_cm"] == pytest.approx(want * Fe.LEG, rel=1e-4)
    assert float(total_on - total_off) == pytest.approx(3.0 * want, rel=1e-4)
    # a target standing higher or lower on its hips is the same pose
    raised = target + torch.tensor([0.0, 0.3, 0.0])
    _, logs_raised, *_ = generate((raised, torch.tensor([True, False])))
    assert logs_raised["paired_cm"] == pytest.approx(logs_on["paired_cm"], rel=1e-4)
    _, logs_none, *_ = generate((target, torch.tensor([False, False])))
    assert logs_none["paired_cm"] == 0.0


def test_paired_motion_term_ignores_posture_and_compares_how_joints_move():
    from training.translator import train as T

    rng = np.random.default_rng(0)
    positions = torch.from_numpy(rng.normal(size=(2, 32, 21, 3)).astype(np.float32))
    hunched = positions + torch.from_numpy(rng.normal(size=(21, 3)).astype(np.float32))
    assert float(T.hips_relative_motion_l1(positions, hunched, 4)) == pytest.approx(0, abs=1e-6)
    assert float(T.hips_relative_l1(positions, hunched)) > 0.1
    # a hand still where the target's moves
    still = positions.clone()
    still[:, :, 15] = still[:, :1, 15]
    assert float(T.hips_relative_motion_l1(still, positions, 4)) > 0.01

    g, d, stats = tiny_networks()
    m, n, x = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2]))
    losses = T.Losses(g, d, T.Standardizer(stats), T.TrainConfig(w_paired_vel=2.0))
    target = torch.randn(2, 32, 21, 3)
    with torch.no_grad():
        torch.manual_seed(1)
        total_off, _, fake_in, _ = losses.generator(m, n, x, paired=None)
        torch.manual_seed(1)
        total_on, logs, *_ = losses.generator(m, n, x, paired=(target, torch.tensor([False, True])))
    pos = disc_positions(fake_in)
    want = float(T.hips_relative_motion_l1(pos[1:], target[1:], 4))
    assert logs["paired_motion_cm"] == pytest.approx(want * Fe.LEG, rel=1e-4)
    assert float(total_on - total_off) == pytest.approx(2.0 * want, rel=1e-4)


def test_translations_to_a_style_without_that_action_move_as_the_content_does():
    from training.translator import train as T

    g, d, stats = tiny_networks()
    m, n, x, r = (random_batch(2, 32, s) for s in ([0, 1], [0, 1], [1, 2], [2, 0]))

    def generate(weight):
        cfg = T.TrainConfig(w_raised_hands=1.0, w_wild_motion=weight)
        with torch.no_grad():
            torch.manual_seed(1)
            return T.Losses(g, d, T.Standardizer(stats), cfg).generator(m, n, x, r=r)

    total_off, logs_off, _, _ = generate(0.0)
    total_on, logs_on, _, wild_in = generate(2.0)
    wild_pos = disc_positions(wild_in)
    want = float(T.hips_relative_motion_l1(wild_pos, m.positions, 4))
    assert logs_off["wild_motion_cm"] == 0.0 and want > 0.0
    assert logs_on["wild_motion_cm"] == pytest.approx(want * Fe.LEG, rel=1e-4)
    assert float(total_on - total_off) == pytest.approx(2.0 * want, rel=1e-4)
