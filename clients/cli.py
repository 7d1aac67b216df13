"""``motion-style``: restyle files or folders through a running service.

    motion-style transfer FILES... (--style NAME | --mix JSON | --style-clip FILE)
                         [--strength S] [GAME OPTIONS] --url URL -o DIR
    motion-style stylize FILES... --style NAME [GAME OPTIONS] --url URL -o DIR

    GAME OPTIONS: --keep-timing (no time warp: as many frames as sent), --root-motion
    keep|in_place, --loop auto|true|false (whether the clip is a cycle to keep looping)
    motion-style dance SONGS... [--genre G] [--skeleton RIG] [--fps N]
                         [--root-motion keep|in_place] --url URL -o DIR

A folder stands for the clips (or songs) in it and below it; each result is written under
DIR with the input's name (and its path below the folder), the extension of what came
back. Requests go out ``--jobs`` at a time. A 503 (or 429) is retried after the
Retry-After the service sends, at most ``--retries`` times and ``--max-wait`` seconds
each. A file that fails is named at the end, with the service's reason, and the others
go on; the exit status is 1 if any failed, 2 for bad arguments. What the service warned
of a file written (its ``X-Warnings``) is printed at the end too, as ``warned: FILE: ...``,
and without ``-q`` what each song was danced to (``danced: SONG: waltz at 86 bpm, ...``).

Where the service needs an API key, give it with ``--api-key`` or ``MOTION_API_KEY`` (the
variable keeps it out of the process list and shell history); it goes out as
``Authorization: Bearer``.
"""

from __future__ import annotations

import argparse
import asyncio
import email.utils
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
from tqdm import tqdm

CLIP_SUFFIXES = (".bvh", ".glb", ".gltf", ".fbx")
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
RETRY_STATUSES = (429, 503)
API_KEY_ENV = "MOTION_API_KEY"
EXTENSIONS = {
    "text/plain": ".bvh",
    "model/gltf-binary": ".glb",
    "model/gltf+json": ".gltf",
    "application/json": ".json",
}
MEDIA_TYPES = {
    ".bvh": "application/octet-stream",
    ".glb": "model/gltf-binary",
    ".gltf": "model/gltf+json",
    ".fbx": "application/octet-stream",
    ".wav": "audio/wav",
    ".flac": "audio/flac",
    ".ogg": "audio/ogg",
    ".mp3": "audio/mpeg",
}


def answer_suffix(response: httpx.Response, fallback: str) -> str:
    """The extension of an answer: its Content-Disposition file name's (an FBX answer is
    ``application/octet-stream``), else its media type's, else ``fallback``."""
    disposition = response.headers.get("content-disposition", "")
    _, _, name = disposition.partition('filename="')
    suffix = Path(name.rstrip('"')).suffix.lower()
    if suffix in (*CLIP_SUFFIXES, ".json"):
        return suffix
    media_type = response.headers.get("content-type", "").split(";")[0].strip()
    return EXTENSIONS.get(media_type, fallback)


@dataclass
class Job:
    """One input file and where its result goes (without the extension)."""

    source: Path
    target: Path


@dataclass
class Outcome:
    job: Job
    written: Path | None = None
    error: str | None = None
    retries: int = 0
    warnings: list[str] = field(default_factory=list)
    danced: str | None = None  # a dance's genre, tempo and beat alignment, as the service says


@dataclass
class Request:
    """What every file's request shares: the endpoint, the fields, the file's field name."""

    path: str
    file_field: str
    fields: dict[str, str] = field(default_factory=dict)
    extra_files: dict[str, tuple[str, bytes, str]] = field(default_factory=dict)


def collect(
    inputs: list[str], suffixes: tuple[str, ...], out_dir: Path
) -> tuple[list[Job], list[str]]:
    """Jobs for the files and folders named (folders searched recursively for ``suffixes``),
    and the inputs that name nothing usable. Two inputs of one name get distinct targets."""
    jobs: list[Job] = []
    problems: list[str] = []
    taken: set[Path] = set()

    def add(source: Path, relative: Path) -> None:
        target = out_dir / relative.with_suffix("")
        stem, n = target, 2
        while target in taken:
            target = stem.with_name(f"{stem.name}-{n}")
            n += 1
        taken.add(target)
        jobs.append(Job(source, target))

    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(
                p for p in path.rglob("*") if p.is_file() and p.suffix.lower() in suffixes
            )
            if not found:
                problems.append(f"{item}: no {', '.join(suffixes)} files in this folder")
            for p in found:
                add(p, p.relative_to(path))
        elif path.is_file():
            add(path, Path(path.name))
        else:
            problems.append(f"{item}: no such file or folder")
    return jobs, problems


def retry_delay(response: httpx.Response, default: float = 1.0) -> float:
    """Seconds the service asks us to wait (Retry-After: seconds or an HTTP date)."""
    value = response.headers.get("retry-after", "").strip()
    if not value:
        return default
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return default
    return max(0.0, when.timestamp() - time.time())


def answer_warnings(response: httpx.Response) -> list[str]:
    """The service's warnings of an answer (``X-Warnings``, a JSON array of strings)."""
    value = response.headers.get("x-warnings")
    if not value:
        return []
    try:
        said = json.loads(value)
    except ValueError:
        return [value]
    return [str(w) for w in said] if isinstance(said, list) else [value]


def dance_facts(response: httpx.Response) -> str | None:
    """``"waltz at 86 bpm, beat alignment 0.61 (chance 0.25)"`` from a dance's headers."""
    genre = response.headers.get("x-dance-genre")
    if not genre:
        return None
    h = response.headers
    return (f"{genre} at {h.get('x-dance-tempo', '?')} bpm, beat alignment "
            f"{h.get('x-beat-alignment', '?')} (chance {h.get('x-beat-alignment-chance', '?')})")  # fmt: skip


def describe_failure(response: httpx.Response) -> str:
    """``"400 Invalid BVH: line 3: ..."`` from a problem document, else the status line."""
    text = f"{response.status_code} {response.reason_phrase}"
    try:
        problem = response.json()
    except ValueError:
        return text
    if isinstance(problem, dict):
        title = problem.get("title") or response.reason_phrase
        detail = problem.get("detail")
        return f"{response.status_code} {title}" + (f": {detail}" if detail else "")
    return text


async def run_one(
    client: httpx.AsyncClient, request: Request, job: Job, args: argparse.Namespace
) -> Outcome:
    outcome = Outcome(job)
    try:
        data = job.source.read_bytes()
    except OSError as exc:
        outcome.error = f"cannot read it: {exc.strerror or exc}"
        return outcome
    media = MEDIA_TYPES.get(job.source.suffix.lower(), "application/octet-stream")
    while True:
        files = {request.file_field: (job.source.name, data, media), **request.extra_files}
        try:
            response = await client.post(request.path, data=request.fields, files=files)
        except httpx.HTTPError as exc:
            outcome.error = f"no answer from {args.url}: {exc}"
            return outcome
        if response.status_code in RETRY_STATUSES and outcome.retries < args.retries:
            delay = retry_delay(response)
            if delay <= args.max_wait:
                outcome.retries += 1
                await asyncio.sleep(delay)
                continue
        if response.status_code != 200:
            outcome.error = describe_failure(response)
            if response.status_code in RETRY_STATUSES:
                outcome.error += f" (gave up after {outcome.retries} retries)"
            elif response.status_code == 401:
                outcome.error += f" (give a key with --api-key or {API_KEY_ENV})"
            return outcome
        suffix = answer_suffix(response, job.source.suffix or ".out")
        target = job.target.with_name(job.target.name + suffix)
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(response.content)
        except OSError as exc:
            outcome.error = f"cannot write {target}: {exc.strerror or exc}"
            return outcome
        outcome.written = target
        outcome.warnings = answer_warnings(response)
        outcome.danced = dance_facts(response)
        return outcome


async def run_all(request: Request, jobs: list[Job], args: argparse.Namespace) -> list[Outcome]:
    limits = httpx.Limits(max_connections=args.jobs, max_keepalive_connections=args.jobs)
    timeout = httpx.Timeout(args.timeout, connect=10.0)
    semaphore = asyncio.Semaphore(args.jobs)
    progress = tqdm(total=len(jobs), unit="file", disable=args.quiet, file=sys.stderr)

    async def bounded(client: httpx.AsyncClient, job: Job) -> Outcome:
        async with semaphore:
            outcome = await run_one(client, request, job, args)
        progress.update(1)
        if outcome.error:
            progress.set_postfix_str(f"failed: {job.source.name}", refresh=True)
        return outcome

    headers = {"Authorization": f"Bearer {args.api_key}"} if args.api_key else {}
    async with httpx.AsyncClient(
        base_url=args.url, timeout=timeout, limits=limits, headers=headers
    ) as client:
        try:
            return list(await asyncio.gather(*(bounded(client, job) for job in jobs)))
        finally:
            progress.close()


def game_fields(args: argparse.Namespace) -> dict[str, str]:
    """The restyling options a game needs, sent only when asked for (the service's
    defaults: the style's time warp, root motion kept, loops found by the service)."""
    fields = {}
    if args.keep_timing:
        fields["time_warp"] = "false"
    if args.root_motion:
        fields["root_motion"] = args.root_motion
    if args.loop:
        fields["loop"] = args.loop
    return fields


def build_request(args: argparse.Namespace) -> Request:
    query = f"?format={args.format}" if getattr(args, "format", None) else ""
    if args.command == "transfer":
        fields = {"strength": repr(args.strength), **game_fields(args)}
        extra = {}
        if args.style:
            fields["style_name"] = args.style
        elif args.mix:
            fields["style_mix"] = args.mix
        else:
            clip = Path(args.style_clip)
            media = MEDIA_TYPES.get(clip.suffix.lower(), "application/octet-stream")
            extra["style"] = (clip.name, clip.read_bytes(), media)
        if args.mapping:
            fields["mapping"] = args.mapping
        return Request("/v1/transfer" + query, "content", fields, extra)
    if args.command == "stylize":
        fields = {"style_name": args.style, **game_fields(args)}
        return Request("/v1/stylize" + query, "content", fields)
    fields = {"fps": repr(args.fps)}
    if args.genre:
        fields["genre"] = args.genre
    if args.seed is not None:
        fields["seed"] = str(args.seed)
    if args.root_motion:
        fields["root_motion"] = args.root_motion
    extra = {}
    if args.skeleton:
        rig = Path(args.skeleton)
        media = MEDIA_TYPES.get(rig.suffix.lower(), "application/octet-stream")
        extra["skeleton"] = (rig.name, rig.read_bytes(), media)
    return Request("/v1/dance" + query, "audio", fields, extra)


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="motion-style",
        description="Restyle animation files or folders through a running motion-style service.",
    )
    commands = top.add_subparsers(dest="command", required=True)

    def common(sub: argparse.ArgumentParser, what: str) -> None:
        sub.add_argument("files", nargs="+", metavar="FILE", help=f"{what} files or folders")
        sub.add_argument("--url", default="http://localhost:8000", help="the service")
        sub.add_argument(
            "--api-key",
            default=os.environ.get(API_KEY_ENV) or None,
            help=f"the service's API key, if it needs one (default: ${API_KEY_ENV})",
        )
        sub.add_argument("-o", "--out", required=True, type=Path, help="folder for the results")
        sub.add_argument("-j", "--jobs", type=int, default=4, help="requests at once (4)")
        sub.add_argument("--retries", type=int, default=5, help="retries of a 503 per file (5)")
        sub.add_argument(
            "--max-wait", type=float, default=60.0, help="longest Retry-After honoured, s (60)"
        )
        sub.add_argument("--timeout", type=float, default=300.0, help="per request, s (300)")
        sub.add_argument("--format", choices=("bvh", "glb", "fbx", "json"), help="answer format")
        sub.add_argument("-q", "--quiet", action="store_true", help="no progress bar")

    def root_motion(sub: argparse.ArgumentParser) -> None:
        sub.add_argument(
            "--root-motion",
            choices=("keep", "in_place"),
            help="keep the travel (the service's default) or hold the hips in place",
        )

    def game(sub: argparse.ArgumentParser) -> None:
        sub.add_argument(
            "--keep-timing",
            action="store_true",
            help="no time warp: the result has the clip's frames and length",
        )
        root_motion(sub)
        sub.add_argument(
            "--loop",
            choices=("auto", "true", "false"),
            help="the clip is a cycle to keep looping (auto: the service finds out)",
        )

    transfer = commands.add_parser("transfer", help="the translator: a style by name, mix or clip")
    common(transfer, "BVH, GLB or FBX")
    style = transfer.add_mutually_exclusive_group(required=True)
    style.add_argument("--style", help="style name or library:style (GET /v1/styles)")
    style.add_argument(
        "--mix", help='styles mixed, JSON name -> weight: \'{"happy": 0.7, "old": 0.3}\''
    )
    style.add_argument("--style-clip", metavar="FILE", help="a clip (BVH, GLB or FBX) in the style")
    transfer.add_argument("--strength", type=float, default=1.0, help="0..1 (1)")
    transfer.add_argument("--mapping", help="JSON joint-name map for rigs not mapped by name")
    game(transfer)
    stylize = commands.add_parser("stylize", help="the fast per-style networks")
    common(stylize, "BVH, GLB or FBX")
    stylize.add_argument(
        "--style", required=True, help="style name or library:style (GET /v1/styles)"
    )
    game(stylize)
    dance = commands.add_parser("dance", help="a dance for each song")
    common(dance, "audio (wav, flac, ogg, mp3)")
    dance.add_argument("--genre", help="dance genre; predicted when absent")
    dance.add_argument("--skeleton", help="BVH, GLB or FBX rig to dance on")
    dance.add_argument("--fps", type=float, default=30.0, help="frame rate (30)")
    dance.add_argument("--seed", type=int, help="random seed")
    root_motion(dance)
    return top


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.jobs < 1 or args.retries < 0 or args.max_wait < 0 or args.timeout <= 0:
        print("motion-style: --jobs must be >= 1, --retries and --max-wait >= 0", file=sys.stderr)
        return 2
    if args.command == "transfer" and not 0.0 <= args.strength <= 1.0:
        print("motion-style: --strength must lie in 0..1", file=sys.stderr)
        return 2
    for option in ("mapping", "mix"):
        value = getattr(args, option, None)
        if value:
            try:
                json.loads(value)
            except ValueError:
                print(f"motion-style: --{option} is not JSON", file=sys.stderr)
                return 2
    suffixes = AUDIO_SUFFIXES if args.command == "dance" else CLIP_SUFFIXES
    jobs, problems = collect(args.files, suffixes, args.out)
    try:
        request = build_request(args)
    except OSError as exc:
        what = "the style clip" if args.command == "transfer" else "the skeleton"
        print(f"motion-style: cannot read {what}: {exc}", file=sys.stderr)
        return 2
    outcomes = asyncio.run(run_all(request, jobs, args)) if jobs else []
    failed = [o for o in outcomes if o.error]
    written = [o for o in outcomes if o.written]
    retries = sum(o.retries for o in outcomes)
    print(
        f"{len(written)} of {len(jobs)} files written to {args.out}"
        + (f"; {retries} retries after 503/429" if retries else ""),
        file=sys.stderr,
    )
    for o in written:
        if o.danced and not args.quiet:
            print(f"danced: {o.job.source}: {o.danced}", file=sys.stderr)
        for w in o.warnings:
            print(f"warned: {o.job.source}: {w}", file=sys.stderr)
    for o in failed:
        print(f"failed: {o.job.source}: {o.error}", file=sys.stderr)
    for p in problems:
        print(f"skipped: {p}", file=sys.stderr)
    return 1 if failed or problems or not jobs else 0


if __name__ == "__main__":
    sys.exit(main())
