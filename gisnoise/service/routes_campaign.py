"""Fit and diagnose jobs on an uploaded campaign (a zip of the SPEC section 3 folder)."""

from __future__ import annotations

import shutil
import stat
import tempfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Annotated, Any

from fastapi import APIRouter, File, Form, Request, UploadFile
from fastapi.concurrency import run_in_threadpool

from gisnoise.jsonio import write_json
from gisnoise.model import cards as gcards
from gisnoise.service.deps import WRITE, State, StateDep
from gisnoise.service.errors import ApiError, request_fields
from gisnoise.service.jobs import JobContext
from gisnoise.service.models import CardRef, JobInfo, PhaseName, SafeId
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse
from gisnoise.service.routes_jobs import JOB_LINKS, job_info
from gisnoise.service.storage import storage_error, storage_failure

if TYPE_CHECKING:
    from gisnoise.measure import Campaign

__all__ = ["router", "unpack_campaign", "run_fit_job", "run_diagnose_job", "MAX_RATIO", "RATIO_FLOOR"]

router = APIRouter(prefix="/jobs", tags=["jobs"])

_MAX_MEMBERS = 100_000
MAX_RATIO = 100
"""Largest compression ratio (unzipped : zipped) of a campaign member and of the whole archive.  Measurement
files compress little: WAV recordings about 1.1:1, ULog and DataFlash logs 2-3:1, level and flight CSV 3-6:1;
a member past 100:1 is padding (a zip bomb), not a campaign."""
RATIO_FLOOR = 1 << 20
"""Members (and archives) up to this size unzipped (1 MiB) are not held to :data:`MAX_RATIO`: a small file of
repeated text may compress far, and costs nothing."""
CAMPAIGN_PARTS = ("flights", "mics")
"""The folders of a campaign (SPEC section 3) unzipped beside its ``campaign.json``; nothing else is."""


def _refuse(status: int, field: str, what: str) -> ApiError:
    return ApiError(status, f"{field}: {what}", field=field, scrub=False)  # member names are the client's own


def _campaign_root(infos: list[zipfile.ZipInfo], field: str) -> PurePosixPath:
    """The folder of the archive's shallowest ``campaign.json`` (macOS resource folders left out)."""
    roots = [PurePosixPath(i.filename).parent for i in infos
             if not i.is_dir() and PurePosixPath(i.filename).name == "campaign.json"
             and "__MACOSX" not in PurePosixPath(i.filename).parts]
    if not roots:
        raise ApiError(422, f"{field}: the archive has no campaign.json", field=field)
    return min(roots, key=lambda r: (len(r.parts), str(r)))


def _used(info: zipfile.ZipInfo, root: PurePosixPath) -> bool:
    """Whether a member is a file the campaign reads: its ``campaign.json`` or a file of ``flights/``,
    ``mics/``."""
    if info.is_dir():
        return False
    p = PurePosixPath(info.filename)
    if root.parts and p.parts[:len(root.parts)] != root.parts:
        return False
    rel = p.parts[len(root.parts):]
    return rel == ("campaign.json",) or (len(rel) > 1 and rel[0] in CAMPAIGN_PARTS)


def _check_members(infos: list[zipfile.ZipInfo], max_bytes: int, field: str) -> None:
    """Refuse what no campaign holds: too many members, too many bytes, names leaving the folder, links,
    a name given twice, members (or an archive) compressed past :data:`MAX_RATIO`."""
    if len(infos) > _MAX_MEMBERS:
        raise ApiError(413, f"{field}: {len(infos)} files exceed the limit of {_MAX_MEMBERS}", field=field)
    total = sum(i.file_size for i in infos)
    if total > max_bytes:
        raise ApiError(413, f"{field}: {total} bytes unzipped exceed the limit of {max_bytes}", field=field)
    seen: set[str] = set()
    for i in infos:
        p = PurePosixPath(i.filename)
        if p.is_absolute() or ".." in p.parts or "\\" in i.filename:
            raise _refuse(422, field, f"member {i.filename!r} leaves the archive folder")
        if stat.S_ISLNK(i.external_attr >> 16):
            raise _refuse(422, field, f"member {i.filename!r} is a link")
        key = str(p) + ("/" if i.is_dir() else "")
        if key in seen:
            raise _refuse(422, field, f"member {i.filename!r} is in the archive more than once (which copy is the "
                                      "campaign's cannot be told); zip each file once")
        seen.add(key)
        if i.file_size > RATIO_FLOOR and i.file_size > MAX_RATIO * max(i.compress_size, 1):
            raise _refuse(413, field, f"member {i.filename!r} unzips to {i.file_size} bytes from "
                                      f"{i.compress_size}, more than {MAX_RATIO}:1 (measurement files compress "
                                      "less than 10:1): refused as padding")
    packed = sum(i.compress_size for i in infos)
    if total > RATIO_FLOOR and total > MAX_RATIO * max(packed, 1):
        raise ApiError(413, f"{field}: the archive unzips to {total} bytes from {packed}, more than {MAX_RATIO}:1 "
                            "(measurement files compress less than 10:1): refused as padding", field=field)


def unpack_campaign(upload: Path, dest: Path, *, max_bytes: int, field: str = "campaign") -> Path:
    """Unzip a campaign safely into ``dest``; returns the folder holding ``campaign.json``.

    Refuses what is not a zip, paths leaving the folder, links, a member name given twice, more than
    ``max_bytes`` unzipped (413), members or archives compressed past :data:`MAX_RATIO` (413) and archives
    without ``campaign.json``.  Only the files the campaign reads are unzipped: the shallowest ``campaign.json``
    and the files of the ``flights/`` and ``mics/`` folders beside it; a member unzipping to more bytes than
    its header states is refused.  A full disk is answered 507 naming the storage.
    """
    try:
        zf = zipfile.ZipFile(upload)
    except (zipfile.BadZipFile, OSError):
        raise ApiError(422, f"{field}: not a zip archive", field=field) from None
    with zf:
        infos = zf.infolist()
        _check_members(infos, max_bytes, field)
        root = _campaign_root(infos, field)
        written = 0
        try:
            for i in infos:
                if not _used(i, root):
                    continue
                target = dest.joinpath(*PurePosixPath(i.filename).parts)
                target.parent.mkdir(parents=True, exist_ok=True)
                n = 0
                with zf.open(i) as src, target.open("wb") as out:
                    while chunk := src.read(1 << 20):
                        n += len(chunk)
                        written += len(chunk)
                        if n > i.file_size:
                            raise _refuse(422, field, f"member {i.filename!r} unzips to more than the "
                                                      f"{i.file_size} bytes its header states")
                        if written > max_bytes:
                            raise ApiError(413, f"{field}: more than {max_bytes} bytes unzipped exceed the limit",
                                           field=field)
                        out.write(chunk)
        except ApiError:
            raise
        except OSError as exc:
            failure = storage_failure(exc, near=dest.parent)
            if failure is not None:
                raise storage_error(failure, "the campaign was not stored") from None
            raise ApiError(422, f"{field}: cannot unzip ({type(exc).__name__}: {exc})", field=field) from None
        except (zipfile.BadZipFile, ValueError, NotImplementedError, zlib.error, EOFError) as exc:
            raise ApiError(422, f"{field}: cannot unzip ({type(exc).__name__}: {exc})", field=field) from None
    return dest.joinpath(*root.parts)


async def _receive_campaign(state: State, campaign: UploadFile) -> Path:
    """The upload unzipped into a fresh folder (moved into the job's input by ``submit``)."""
    s = state.settings
    try:
        tmp = Path(tempfile.mkdtemp(prefix="upload-", dir=s.jobs_dir))
    except OSError as exc:
        failure = storage_failure(exc, near=s.jobs_dir)
        if failure is not None:
            raise storage_error(failure, "the campaign was not stored") from None
        raise
    try:
        zpath = tmp / "campaign.zip"
        n = 0
        with zpath.open("wb") as f:
            while chunk := await campaign.read(1 << 20):
                n += len(chunk)
                if n > s.max_upload_bytes:
                    raise ApiError(413, f"campaign: upload exceeds the limit of {s.max_upload_bytes} bytes",
                                   field="campaign")
                f.write(chunk)
        folder = await run_in_threadpool(unpack_campaign, zpath, tmp / "unzipped", max_bytes=s.max_unzipped_bytes)
        zpath.unlink()
        # keep only the campaign folder itself
        final = tmp / "campaign"
        shutil.move(str(folder), str(final))
        shutil.rmtree(tmp / "unzipped", ignore_errors=True)
        return final
    except OSError as exc:  # a full disk, say: nothing of the upload is left
        shutil.rmtree(tmp, ignore_errors=True)
        failure = storage_failure(exc, near=s.jobs_dir)
        if failure is not None:
            raise storage_error(failure, "the campaign was not stored") from None
        raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _submit(request: Request, state: State, kind: str, params: dict[str, Any], campaign_dir: Path,
            extra: dict[str, bytes] | None = None) -> JSONResponse:
    try:
        job = state.jobs.submit(kind, params, {"campaign": campaign_dir, **(extra or {})})
    finally:
        shutil.rmtree(campaign_dir.parent, ignore_errors=True)
    info = job_info(request, job)
    return JSONResponse(info.model_dump(), status_code=202, headers={"Location": info.url})


@router.post("/fit", status_code=202, response_model=JobInfo, dependencies=WRITE, responses={202: {"links": JOB_LINKS}},
             summary="Fit a model card to an uploaded campaign (job)")
async def fit_job(request: Request, state: StateDep,
                  campaign: Annotated[UploadFile, File(description="Zipped campaign folder (campaign.json, "
                                                                   "flights/, mics/).")],
                  phase: Annotated[PhaseName, Form(description="Flight phase to fit.")],
                  ansatz: Annotated[str, Form(max_length=100, description="Ansatz name.")] = "paper-offset",
                  card_id: Annotated[SafeId | None, Form(description="Id of the fitted card.")] = None,
                  report: Annotated[bool, Form(description="Also write the fit report (report.html, "
                                                           "figures).")] = False,
                  ) -> JSONResponse:
    from gisnoise.model import get_ansatz

    try:
        get_ansatz(ansatz)
    except Exception as exc:  # noqa: BLE001 - an unknown name, reported with the field
        raise ApiError(422, f"ansatz: {exc}", field="ansatz") from None
    if card_id is not None:
        from gisnoise.service.cardstore import check_id

        check_id(card_id, "card_id")
    folder = await _receive_campaign(state, campaign)
    return _submit(request, state, "fit", {"phase": phase, "ansatz": ansatz, "card_id": card_id,
                                           "report": report}, folder)


@router.post("/diagnose", status_code=202, response_model=JobInfo, dependencies=WRITE,
             responses={202: {"links": JOB_LINKS}},
             summary="Diagnose a card against an uploaded campaign (job)")
async def diagnose_job(request: Request, state: StateDep,
                       campaign: Annotated[UploadFile, File(description="Zipped campaign folder.")],
                       card_id: Annotated[CardRef | None, Form(description="Card in the store "
                                                                          "('id' or 'id@version').")] = None,
                       card: Annotated[UploadFile | None, File(description="Or a card JSON file.")] = None,
                       report: Annotated[bool, Form(description="Also write report.html and its "
                                                                "figures.")] = True,
                       ) -> JSONResponse:
    if (card_id is None) == (card is None):
        raise ApiError(422, "card_id: give either card_id or a card file", field="card_id")
    if card is not None:
        text = await card.read(10_000_001)
        if len(text) > 10_000_000:
            raise ApiError(413, "card: card file exceeds 10 MB", field="card")
        try:
            raw = text.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise ApiError(422, "card: the card file is not UTF-8 JSON text", field="card") from None
        try:
            mc = gcards.loads(raw, source="card")
        except gcards.CardError as exc:
            raise ApiError(422, str(exc), field=f"card.{exc.field}" if exc.field else "card") from None
    else:
        assert card_id is not None
        mc = state.cards.resolve(card_id, field="card_id")
    from gisnoise.diagnose import check_diagnosable

    with request_fields({"card": "card_id" if card is None else "card"}):
        check_diagnosable(mc)  # the card is known now: a hemisphere is refused before the upload is read
    folder = await _receive_campaign(state, campaign)
    return _submit(request, state, "diagnose", {"card": mc.id, "report": report}, folder,
                   {"card.json": gcards.dumps(mc).encode()})


# ------------------------------------------------------------------ handlers
CAMPAIGN_FIELDS = {"phase": "phase", "ansatz": "ansatz"}
"""A core error met while reading the uploaded campaign names a field of its files (a WAV header's ``length``,
a CSV's ``t``): the request's field is ``campaign`` (the message names the file and what is wrong in it)."""


def _read_campaign(ctx: JobContext) -> Campaign:
    """The job's stored campaign, read as the command line reads it; a cancel is seen between its files."""
    from gisnoise.measure import read_campaign

    with request_fields(CAMPAIGN_FIELDS, default="campaign"):
        return read_campaign(ctx.input_dir / "campaign", progress=lambda done, total: ctx.check_cancel())


def _log_warnings(ctx: JobContext, camp: Campaign) -> list[str]:
    """The campaign's log warnings (:func:`gisnoise.measure.campaign_log_warnings`, the lines the command
    line prints), each log named as in the client's upload (``upload/campaign/flights/<file>``), not by the
    server's folder."""
    from gisnoise.measure import campaign_log_warnings

    with request_fields(CAMPAIGN_FIELDS, default="campaign"):
        warnings = campaign_log_warnings(camp)
    for folder in (ctx.input_dir.resolve(), ctx.input_dir):
        _strip_server_paths(warnings, str(folder))
    return warnings


def run_fit_job(ctx: JobContext) -> dict[str, Any]:
    """Fit the stored campaign; writes card.json (the fitted card) and fit.json (a summary).

    The summary (the job's result and fit.json) carries ``warnings``: the campaign's log warnings
    (:func:`_log_warnings`), then the fit's own (a microphone the model misses alone, as ``gisnoise fit`` prints
    them), empty when there are none.
    """
    from gisnoise.identify import fit_campaign

    p = ctx.params
    max_iter = 100

    def progress(iteration: int, cost: float) -> None:
        ctx.progress(min(0.1 + 0.85 * iteration / max_iter, 0.95), f"iteration {iteration}, cost {cost:.6g}")

    ctx.progress(0.0, "reading the campaign")
    camp = _read_campaign(ctx)
    warnings = _log_warnings(ctx, camp)
    ctx.warnings = warnings  # the campaign is read: a job that then fails keeps them (none: an empty list)
    result = fit_campaign(camp, p["phase"], ansatz=p["ansatz"], max_iter=max_iter, progress=progress,
                          cancel=ctx.cancel)
    ctx.check_cancel()
    warnings = warnings + [str(w) for w in result.info.get("warnings") or []]
    data = result.info.get("data")
    if isinstance(data, dict):  # the server's folder means nothing to the client
        data["campaign"] = f"uploaded campaign (job {ctx.job.id})"
    card = result.to_card(id=p.get("card_id") or None, phase=p["phase"])
    gcards.save(card, ctx.output_dir / "card.json")
    summary: dict[str, Any] = {"card_id": card.id, "phase": card.phase, "ansatz": card.ansatz,
                               "parameters": dict(card.parameters), "std": card.std, "warnings": warnings}
    for k in ("success", "n", "cost", "aic", "bic", "message"):
        v = getattr(result, k, None)
        if isinstance(v, (bool, int, float, str)):
            summary[k] = v
    held = result.info.get("held_parameters")
    if held:  # their std of 0 means 'not estimated': say why, as the card does
        summary["held_parameters"] = dict(held)
    if p.get("report"):
        ctx.progress(0.96, "writing the report")
        summary["report"] = _report("gisnoise.identify.report", result, ctx.output_dir / "report")
    write_json(summary, ctx.output_dir / "fit.json", indent=2)
    return summary


def _report(module: str, *args: Any, **kw: Any) -> str:
    """Call ``write_report`` of a report module; a missing plotting library is said, not hidden."""
    import importlib

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return "not written: matplotlib is not installed (the 'plot' extra)"
    importlib.import_module(module).write_report(*args, **kw)
    return "written"


def run_diagnose_job(ctx: JobContext) -> dict[str, Any]:
    """Diagnose the stored card against the stored campaign: diagnosis.json (and report.html), as the CLI.

    The summary (the job's result) carries ``warnings``: the campaign's log warnings (:func:`_log_warnings`),
    empty when there are none.
    """
    from gisnoise.diagnose import run_diagnosis, with_mic_heights, write_diagnosis

    card = gcards.load(ctx.input_dir / "card.json")
    ctx.progress(0.0, "reading the campaign")
    camp = _read_campaign(ctx)
    warnings = _log_warnings(ctx, camp)
    ctx.warnings = warnings  # the campaign is read: a job that then fails keeps them (none: an empty list)

    def progress(done: int, total: int, what: str = "") -> None:
        ctx.progress(0.9 * done / max(total, 1), what or "diagnosing")

    with request_fields(CAMPAIGN_FIELDS, default="campaign"):
        samples = with_mic_heights(camp.samples(), ctx.input_dir / "campaign")
    diag = run_diagnosis(samples, card, progress=progress, cancel=ctx.cancel)
    ctx.check_cancel()
    _strip_server_paths(diag.result, str(ctx.input_dir))  # the server's folder means nothing to the client
    write_diagnosis(diag, ctx.output_dir, campaign=f"uploaded campaign (job {ctx.job.id})")
    summary = {"card": card.id, "verdict": diag.result.get("verdict"), "baseline": diag.result.get("baseline"),
               # what the diagnosis found wrong in campaign.json (a position, a height, a clock), as the CLI says it
               "contradictions": list((diag.result.get("metadata") or {}).get("contradictions") or []),
               "warnings": warnings}
    if ctx.params.get("report", True):
        ctx.progress(0.9, "writing the report")
        summary["report"] = _report("gisnoise.diagnose.report", diag, ctx.output_dir,
                                    progress=lambda d, t: ctx.progress(0.9 + 0.1 * d / max(t, 1), "writing the report"))
    return summary


def _strip_server_paths(doc: Any, prefix: str) -> None:
    """Replace the server's job folder in strings of a result document (in place)."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            if isinstance(v, str) and prefix in v:
                doc[k] = v.replace(prefix, "upload")
            else:
                _strip_server_paths(v, prefix)
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            if isinstance(v, str) and prefix in v:
                doc[i] = v.replace(prefix, "upload")
            else:
                _strip_server_paths(v, prefix)
