"""Genre the dance network cannot ignore (training.dance_genre): swapped windows, the
convolutional judge, kinetic prior, diversity guard and free skating, the genre FiLM layers
and fine-tuning a network that had none."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion import dance_features as DF
from motion import retarget
from tests.rigs import load_fixture

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def walk():
    m = load_fixture()
    return retarget.to_canonical(m, retarget.make_rig(m.skeleton, m))


def test_swapped_windows_are_music_windows_asked_another_music_genre():
    from training import dance_genre as TG

    rng = np.random.default_rng(0)
    genre = torch.from_numpy(rng.integers(0, len(DF.GENRES), 2000))
    music = genre < len(DF.MUSIC_GENRES)
    asked = genre.clone()
    swapped = TG.swap_genres(asked, music, 0.5, rng)
    assert not swapped[~music].any()
    assert 0.4 < swapped[music].float().mean() < 0.6
    assert (asked[swapped] != genre[swapped]).all() and (asked[swapped] < 4).all()
    assert (asked[~swapped] == genre[~swapped]).all()
    # every other music genre is asked
    assert set(asked[swapped].tolist()) == set(range(len(DF.MUSIC_GENRES)))


def test_judge_separates_genres_by_their_motion_and_bounds_each_genre():
    """The convolutional judge tells genres apart by how joints move over time (here, one
    frequency each, the same mean and deviation), the kinetic prior is zero inside a genre's
    band and grows outside it, the diversity guard fires only when windows asked one genre
    collapse together, and skating is penalised only beyond the real windows'."""
    from training import dance_genre as TG

    gen = torch.Generator().manual_seed(0)
    genre = torch.arange(400) % 4
    t = torch.arange(24).float()
    phase = torch.rand(400, 1, 1, generator=gen) * 6.28
    freq = (0.6 + 0.4 * genre.float())[:, None, None]
    frames = torch.sin(freq * t[None, :, None] + phase) + 0.1 * torch.randn(
        400, 24, 6, generator=gen
    )
    centres = torch.randn(4, 10, generator=gen) * 3
    kinetic = centres[genre] + torch.randn(400, 10, generator=gen)
    skate = 0.1 + 0.05 * genre.float()
    judge = TG.ConvJudge(6, 10, width=16)
    assert judge.fit(frames, kinetic, skate, genre, steps=300) > 0.95
    assert not any(p.requires_grad for p in judge.parameters())
    # the window statistics of the other family carry nothing here: every channel's mean
    # and deviation over the window are the same for each genre
    assert frames.std(1).mean(-1)[genre == 0].mean() == pytest.approx(
        frames.std(1).mean(-1)[genre == 3].mean(), abs=0.05)  # fmt: skip
    z = centres[genre[:8]]
    assert float(judge.prior(z, genre[:8])) == 0.0
    assert float(judge.prior(z + 10.0 * judge.kin_std, genre[:8])) > 1.0
    # the genre's own windows match its mean; windows that all move less do not
    assert float(judge.match(kinetic[genre == 1], genre[genre == 1])) < 0.05
    assert float(judge.match(kinetic[genre == 1] - 2.0 * judge.kin_std, genre[genre == 1])) > 1.0
    # the judge stops pushing once it names the asked genre with 80 % or more
    sure = torch.tensor([[4.0, 0.0, 0.0, 0.0]])
    assert float(judge.judged(sure, torch.tensor([0]))) == 0.0
    assert float(judge.judged(sure, torch.tensor([1]))) > 3.0
    spread = kinetic[genre == 2]
    assert float(judge.diversity(spread, genre[genre == 2])) == 0.0
    same = spread[:1].expand(6, -1) + 0.01 * torch.randn(6, 10, generator=gen)
    assert float(judge.diversity(same, torch.full((6,), 2))) > 0.5
    allowed = judge.genre_skate
    assert float(judge.skating(allowed[:2], torch.tensor([0, 1]))) == 0.0
    assert float(judge.skating(allowed[:2] + 0.5, torch.tensor([0, 1]))) == pytest.approx(0.5)
    # no genre is allowed more skating than the median genre
    assert float(allowed.max()) <= float(torch.median(skate.unique())) + 1e-6


def test_free_skating_is_the_stillest_foot_point_on_the_floor():
    from training import dance_genre as TG

    pos = torch.zeros(1, 11, 5, 3)
    raw = torch.zeros(1, 11, DF.MOTION_CHANNELS)
    pos[0, :, 1, 0] = torch.arange(11) / DF.FPS  # point 1 glides at 1 leg length a second
    pos[0, :, 2, 0] = torch.arange(11) * 2 / DF.FPS
    assert float(TG.free_skating(pos, raw, [1, 2])[0]) == pytest.approx(1.0)
    assert float(TG.free_skating(pos, raw, [0, 1])[0]) == 0.0
    raw[..., DF.VELOCITY.start] = -1.0  # the body travels back as point 1 glides forward
    assert float(TG.free_skating(pos, raw, [1, 2])[0]) == pytest.approx(0.0, abs=1e-6)


def _stats(walk):
    m = DF.encode(walk).features
    a = np.random.default_rng(0).normal(size=(len(m), DF.AUDIO_CHANNELS)).astype(np.float32)
    return DF.DanceStats.fit([a], [m]), m, a


def test_film_starts_as_the_network_it_fine_tunes(tmp_path, walk):
    """A FiLM network initialised from a checkpoint without FiLM steps exactly as it did, and
    a checkpoint of another shape is refused."""
    from training import dance as TD

    torch.manual_seed(0)
    stats, m, _ = _stats(walk)
    plain = TD.DanceNet(TD.Config(hidden=32, code=16, audio_hidden=32)).eval()
    path = tmp_path / "plain.pt"
    torch.save({"model": plain.state_dict(), "net_config": {"hidden": 32, "code": 16,
                "audio_hidden": 32}, "stats": stats.arrays(), "start_poses": m[:2]}, path)  # fmt: skip
    film, _, ckpt = TD.init_from(path, TD.Config(film=True))
    film.eval()
    assert film.config.film and film.config.hidden == 32 and len(ckpt["start_poses"]) == 2
    code = torch.randn(2, 16)
    genre = torch.eye(len(DF.GENRES))[[0, 3]]
    prev = torch.randn(2, DF.MOTION_CHANNELS)
    with torch.no_grad():
        want = plain.step(code, genre, prev, *plain.init_state(2))
        got = film.step(code, genre, prev, *film.init_state(2))
    for w, g in zip(want, got, strict=True):
        torch.testing.assert_close(w, g)
    other = TD.DanceNet(TD.Config(hidden=32, code=8, audio_hidden=32))
    torch.save({"model": other.state_dict(), "net_config": {"hidden": 32, "code": 16,
                "audio_hidden": 32}, "stats": stats.arrays(), "start_poses": m[:2]}, path)  # fmt: skip
    with pytest.raises(RuntimeError):
        TD.init_from(path, TD.Config(film=True))


def test_swapped_windows_train_the_film_layers_through_the_judge(walk):
    from training import dance as TD
    from training import dance_genre as TG
    from training.dance_data import Sequence, WindowSampler
    from training.dance_losses import Losses

    torch.manual_seed(0)
    stats, m, a = _stats(walk)
    seqs = [Sequence(f"walk{g}", g, a, m, True, True) for g in range(len(DF.MUSIC_GENRES))]
    losses = Losses(stats)
    args = TD.parse_args(["--window", "24", "--swap-share", "1.0", "--w-judge", "1", "--w-prior",
                          "1", "--w-match", "1", "--w-diversity", "1", "--w-free-skate", "1",
                          "--guard-all", "--warm", "4",
                          "--cond-ramp", "1"])  # fmt: skip
    judge = TG.fit_judge(WindowSampler(seqs, stats, 24, 0.0, 1), WindowSampler(seqs, stats, 24, 0.0, 2),
                         losses, skip=args.warm - 1, batches=2, steps=20)  # fmt: skip
    model = TD.DanceNet(TD.Config(hidden=32, code=16, audio_hidden=32, film=True))
    weights = {k: getattr(args, f"w_{k}") for k in TD.WEIGHTS}
    batch = WindowSampler(seqs, stats, 24, 0.0, 3).batch(6)
    parts = TD.train_step(model, losses, batch, args, np.random.default_rng(0), 0, weights, judge)
    assert all(torch.isfinite(v) for v in parts.values())
    assert float(parts["judge"].detach()) > 0
    assert float(parts["feat"]) == 0.0  # every window swapped: nothing to reconstruct
    for name in ("prior", "match", "diversity", "free_skate"):
        assert torch.isfinite(parts[name]) and float(parts[name].detach()) >= 0.0
    parts["total"].backward()
    assert model.film2.weight.grad.abs().sum() > 0  # the asked genre reaches the output
    val = TD.validate(model, losses, [batch], judge)
    assert 0.0 <= val["swapped_judged"] <= 1.0


def test_schedule_stages_are_training_flags():
    """Every flag of the shipped schedule is one ``training.dance`` accepts, with its value."""
    from training import dance as TD
    from training import dance_schedule as DS

    stages = DS.load_schedule()
    names = [s["name"] for s in stages]
    assert names[0] == "base"
    for i, stage in enumerate(stages):
        if "blend" in stage:  # blends stages before it
            spec = stage["blend"]
            assert {spec["from"], *spec["tuned"]} <= set(names[:i]) and 0 < spec["weight"] <= 1
            continue
        assert stage.get("from", names[max(i - 1, 0)]) in names[: max(i, 1)]
        args = TD.parse_args(DS.stage_argv(stage))
        for name, value in stage["flags"].items():
            assert getattr(args, name.replace("-", "_")) == value
    assert DS.stage_argv({"flags": {"film": True, "steps": 5}}) == ["--film", "--steps", "5"]


def test_the_schedule_passes_the_device_and_the_carried_file_to_every_stage(tmp_path, monkeypatch):
    """On a lent machine every stage trains on its device from the carried sequences."""
    import json

    from training import dance as TD
    from training import dance_schedule as DS

    runs = []
    monkeypatch.setattr(TD, "main", lambda argv: runs.append(argv) or 0)
    monkeypatch.setattr(DS, "stages_of", lambda path, fold=0: ([], None))
    schedule = tmp_path / "schedule.json"
    schedule.write_text(json.dumps({"stages": [{"name": "base", "flags": {"steps": 2}},
                                               {"name": "more", "flags": {"steps": 3}}]}))  # fmt: skip
    with pytest.raises(SystemExit, match="stopped before its last step"):  # nothing trained
        DS.main(["--schedule", str(schedule), "--work", str(tmp_path), "--device", "cuda",
                 "--prepared", "cache/carry/dance_prepared.npz"])  # fmt: skip
    args = TD.parse_args(runs[0])
    assert (args.device, args.prepared, args.steps) == (
        "cuda",
        Path("cache/carry/dance_prepared.npz"),
        2,
    )


def test_a_blend_moves_the_start_towards_the_mean_of_its_fine_tunings():
    from training import dance as TD
    from training import dance_schedule as DS

    torch.manual_seed(0)
    start = {"model": TD.DanceNet(TD.Config()).state_dict(), "stages": ["base"], "step": 80}
    tuned = [{"model": TD.DanceNet(TD.Config(film=True)).state_dict(), "stages": ["base", n],
              "net_config": {"film": True}, "step": 10} for n in ("a", "b")]  # fmt: skip
    out = DS.blend(start, tuned, 0.6)
    assert out["step"] == 100  # every stage's steps
    mean = (tuned[0]["model"]["out.weight"] + tuned[1]["model"]["out.weight"]) / 2
    want = 0.4 * start["model"]["out.weight"] + 0.6 * mean
    torch.testing.assert_close(out["model"]["out.weight"], want)
    film = (tuned[0]["model"]["film1.weight"] + tuned[1]["model"]["film1.weight"]) / 2
    torch.testing.assert_close(out["model"]["film1.weight"], 0.6 * film)  # zero in the start
    assert out["net_config"] == {"film": True} and set(out["model"]) == set(tuned[0]["model"])
    TD.DanceNet(TD.Config(film=True)).load_state_dict(out["model"])


def test_the_schedule_replays_branches_and_a_blend_and_resumes(tmp_path, monkeypatch):
    """A tiny schedule of the shipped one's shape (a base, two fine-tunings of it, their
    blend) on the real dances, fold 1: the checkpoint is the blend of the stage checkpoints,
    every stage is fold 1's and no fold-0 stage may start from them, a second replay trains
    nothing, and a lost stage is trained again alone."""
    import functools
    import json

    from tests.conftest import data_path
    from training import dance as TD
    from training import dance_genre as TG
    from training import dance_schedule as DS

    data_path("dance-with-melody")  # skips without the dance data
    # the fine-tunings' judge, fitted on a few real windows: the replay is tested, not the judge
    monkeypatch.setattr(TG, "fit_judge", functools.partial(TG.fit_judge, batches=4, steps=20))
    small = {"steps": 2, "batch": 2, "window": 32, "cond-ramp": 1, "val-every": 1000,
             "save-every": 1000}  # fmt: skip
    tuning = {**small, "film": True, "swap-share": 0.5, "w-judge": 0.2}
    schedule = tmp_path / "schedule.json"
    schedule.write_text(json.dumps({"stages": [
        {"name": "base", "flags": {**small, "seed": 0}},
        {"name": "genre-1", "from": "base", "flags": {**tuning, "seed": 1}},
        {"name": "genre-2", "from": "base", "flags": {**tuning, "seed": 2}},
        {"name": "blend", "blend": {"from": "base", "tuned": ["genre-1", "genre-2"],
                                    "weight": 0.6}},
    ]}))  # fmt: skip
    work, out = tmp_path / "work", tmp_path / "dance.pt"
    argv = ["--schedule", str(schedule), "--work", str(work), "--out", str(out), "--fold", "1"]
    assert DS.main(argv) == 0
    load = lambda p: torch.load(p, map_location="cpu", weights_only=False)  # noqa: E731
    got, base = load(out), load(work / "base.pt")
    tuned = [load(work / f"genre-{s}.pt") for s in (1, 2)]
    assert got["stages"] == ["base", "genre-1", "genre-2", "blend"]
    assert [TD.fold_of(c) for c in (base, *tuned, got)] == [1, 1, 1, 1]
    with pytest.raises(SystemExit, match="fold 1's, not fold 0's"):  # it saw fold 0's songs
        TD.main(["--init", str(work / "base.pt"), "--checkpoint", str(tmp_path / "x.pt")])
    with pytest.raises(SystemExit, match="fold 1's, not fold 0's"):  # nor a fold-0 replay
        DS.main(argv[:-2])
    assert tuned[0]["train_config"]["init"] == str(work / "base.pt")
    assert tuned[1]["train_config"]["init"] == str(work / "base.pt")
    assert not torch.equal(tuned[0]["model"]["out.weight"], tuned[1]["model"]["out.weight"])
    want = 0.4 * base["model"]["out.weight"] + 0.3 * sum(t["model"]["out.weight"] for t in tuned)
    torch.testing.assert_close(got["model"]["out.weight"], want)
    stamps = {p.name: p.stat().st_mtime_ns for p in work.glob("*.pt")}
    assert DS.main(argv) == 0  # everything done: nothing trained
    assert {p.name: p.stat().st_mtime_ns for p in work.glob("*.pt")} == stamps
    (work / "genre-2.pt").unlink()
    out.unlink()
    assert DS.main(argv) == 0
    assert (work / "base.pt").stat().st_mtime_ns == stamps["base.pt"]
    assert (work / "genre-1.pt").stat().st_mtime_ns == stamps["genre-1.pt"]
    assert load(out)["stages"] == ["base", "genre-1", "genre-2", "blend"]


def test_a_stage_stops_at_its_stop_step_and_a_resumed_run_never_passes_it():
    from training import dance as TD

    args = TD.parse_args(["--steps", "1600", "--stop-step", "1000"])
    assert TD.run_bounds(0, args) == (1000, 1000)
    args = TD.parse_args(["--steps", "1600", "--stop-step", "1000", "--max-steps", "300"])
    assert TD.run_bounds(0, args) == (1000, 300)
    assert TD.run_bounds(900, args) == (1000, 1000)
    assert TD.run_bounds(0, TD.parse_args(["--steps", "50"])) == (50, 50)
