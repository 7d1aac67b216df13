"""Speed of dance generation (jacob2019 made to work) for a whole song, without HTTP:
frames per second of the result for a 3-minute song, and the milliseconds of each stage.

    python -m bench.bench_dance [--seconds 180] [--repeats 3] [--format wav] [--json]

One run = what ``POST /v1/dance`` does after reading the upload: decode the audio ->
per-frame features and beats -> audio network -> the step network run autoregressively
in onnxruntime for every frame -> smoothing and decoding -> beat warp -> foot clean-up
(IK) -> write the BVH. The song is synthetic (``training/songs.py``: drums, bass, chords at
112 bpm) so the figure does not depend on the shared data. Uses the shipped
``models/dance``; no torch.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from motion import bvh


def main(argv: list[str] | None = None) -> dict:
    from service import limits
    from service.config import Settings
    from service.engines.dance import DanceEngine, DanceJob
    from service.manifest import load_manifest
    from service.metrics import StageTimer
    from training.songs import encoded, song

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=180.0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--format", default="wav", choices=("wav", "flac", "ogg", "mp3"))
    p.add_argument("--genre", default="waltz")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    settings = Settings(max_audio_seconds=max(args.seconds + 1, Settings().max_audio_seconds))
    models = settings.models_dir[0]  # the first model folder: the shipped one by default
    entry = next((m for m in load_manifest(models).models if m.family == "dance"), None)
    if entry is None:
        raise SystemExit(f"no dance model in {models}/manifest.json")
    engine = DanceEngine(entry, models, settings)
    engine.load()
    data = encoded(song(args.seconds), args.format.upper())

    def once() -> tuple[float, dict, int]:
        started = time.perf_counter()
        timer = StageTimer(engine.name)
        with timer.stage("decode_audio"):
            samples, sr = limits.decode_audio(data, settings)
        result = engine.predict(DanceJob(samples, sr, genre=args.genre), timer)
        with timer.stage("write"):
            bvh.dumps(result.motion)
        return time.perf_counter() - started, dict(timer.ms), result.motion.num_frames

    once()  # warm-up
    runs = [once() for _ in range(args.repeats)]
    seconds = statistics.median(r[0] for r in runs)
    frames = runs[0][2]
    report = {
        "model": f"{engine.name}/{engine.version}",
        "song_seconds": args.seconds,
        "format": args.format,
        "frames": frames,
        "repeats": args.repeats,
        "intra_op_threads": settings.intra_op_threads,
        "seconds": round(seconds, 3),
        "frames_per_s": round(frames / seconds, 1),
        "realtime_factor": round(args.seconds / seconds, 1),
        "stages_ms": {
            k: round(statistics.median(r[1].get(k, 0.0) for r in runs), 1) for k in runs[0][1]
        },
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        stages = ", ".join(f"{k} {v:.0f}" for k, v in report["stages_ms"].items())
        print(
            f"{report['model']}: {args.seconds:.0f} s {args.format} song -> {frames} frames in "
            f"{seconds:.2f} s (median of {args.repeats}): {report['frames_per_s']:.0f} frames/s, "
            f"{report['realtime_factor']:.0f}x real time\n  ms: {stages}"
        )
    return report


if __name__ == "__main__":
    main()
