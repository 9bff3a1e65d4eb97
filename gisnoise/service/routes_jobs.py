"""Jobs: list, status with progress, result download, cancel, delete."""

from __future__ import annotations

import mimetypes
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response
from fastapi import Path as PathParam
from fastapi.responses import FileResponse

from gisnoise.service.deps import WRITE, State, StateDep
from gisnoise.service.errors import ApiError
from gisnoise.service.jobs import Job
from gisnoise.service.models import ErrorBody, FileName, JobError, JobInfo, JobList, MediaType, SafeId

router = APIRouter(prefix="/jobs", tags=["jobs"])

_MEDIA = {".geojson": MediaType.geojson.value, ".tif": MediaType.geotiff.value, ".json": MediaType.json.value,
          ".zip": MediaType.zip.value, ".csv": MediaType.csv.value, ".html": MediaType.html.value,
          ".png": MediaType.png.value}

JOB_LINKS = {name: {"operationId": op, "parameters": {"job_id": "$response.body#/id"}}
             for name, op in (("GetJob", "get_job"), ("JobResult", "job_result"), ("CancelJob", "cancel_job"))}
"""OpenAPI links from a 202 (job queued) to the job's operations."""

MAIN_RESULT = {"contours": ("contours.geojson", "levels.tif"), "fit": ("card.json",),
               "diagnose": ("diagnosis.json",)}
"""Result file of each job kind served by ``/jobs/{id}/result`` (first = default)."""


def job_info(request: Request, job: Job) -> JobInfo:
    url = str(request.url_for("get_job", job_id=job.id))
    err = None
    if job.error is not None:
        err = JobError(detail=job.error, field=job.error_field, status=job.error_status)
    message = RESULT_MISSING if job.result_missing else job.message
    return JobInfo(
        id=job.id, kind=job.kind, status=job.status, progress=job.progress, message=message,  # type: ignore[arg-type]
        created=job.created, started=job.started, finished=job.finished, attempts=job.attempts,
        cancel_requested=job.cancel_requested, error=err, summary=dict(job.summary) if job.summary else None,
        files=list(job.files), url=url,
        result_url=url + "/result" if job.status == "succeeded" and not job.result_missing else None,
    )


RESULT_MISSING = "done, but its result is missing on the server (its folder was removed)"
"""The message of a succeeded job whose result folder is gone."""


JobId = Annotated[SafeId, PathParam(description="Job id.")]


def _get(state: State, job_id: str) -> Job:
    job = state.jobs.get(job_id) if job_id.isalnum() else None
    if job is None:
        raise ApiError(404, f"job_id: no job {job_id!r}", field="job_id")
    return job


@router.get("", response_model=JobList, summary="List jobs, newest first")
def list_jobs(request: Request, state: StateDep,
              status: str | None = Query(None, pattern="^(queued|running|succeeded|failed|cancelled)$"),
              kind: str | None = Query(None, pattern="^(contours|fit|diagnose)$"),
              limit: int = Query(50, ge=1, le=1000), offset: int = Query(0, ge=0, le=10**9)) -> JobList:
    jobs = state.jobs.list(status=status, kind=kind, limit=limit, offset=offset)
    return JobList(jobs=[job_info(request, j) for j in jobs], total=state.jobs.count(status=status, kind=kind))


@router.get("/{job_id}", response_model=JobInfo, summary="A job's status and progress", operation_id="get_job")
def get_job(job_id: JobId, request: Request, state: StateDep) -> JobInfo:
    return job_info(request, _get(state, job_id))


def _file_response(path: Path) -> FileResponse:
    media = _MEDIA.get(path.suffix.lower()) or mimetypes.guess_type(path.name)[0] or MediaType.octet.value
    return FileResponse(path, media_type=media, filename=path.name)


def _result_path(state: State, job: Job, name: str, field: str = "name") -> Path:
    """The result file ``name`` of ``job``; errors about the name say ``field`` (``job_id`` for the main result,
    which the client does not name)."""
    if job.status != "succeeded":
        if job.status == "failed":
            raise ApiError(409, f"job_id: job {job.id} failed, it has no result: {job.error}", field="job_id")
        if job.status == "cancelled":
            raise ApiError(409, f"job_id: job {job.id} was cancelled; it has no result", field="job_id")
        raise ApiError(409, f"job_id: job {job.id} is {job.status}; no result yet", field="job_id")
    if job.result_missing:
        raise ApiError(410, f"job_id: the result of job {job.id} is missing on the server (its folder was removed "
                            "after the job succeeded); submit the job again", field="job_id")
    # the name is looked up in the job's listing, never joined to a path as given
    listed = {f: f for f in job.files}
    if name not in listed:
        if field == "job_id":  # the job's main result, named by its kind: it was there when the job succeeded
            raise ApiError(410, f"job_id: the result file {name!r} of job {job.id} is missing on the server (it "
                                f"was removed after the job succeeded; files: {', '.join(job.files) or 'none'})",
                           field="job_id")
        raise ApiError(404, f"name: job {job.id} has no result file {name!r} (files: {', '.join(job.files)})",
                       field="name")
    path = state.jobs.result_dir(job.id) / listed[name]
    if not path.is_file():
        raise ApiError(410, f"{field}: the result file {name!r} of job {job.id} is missing on the server (it was "
                            "removed after the job succeeded)", field=field)
    return path


_RESULT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {m.value: {} for m in (MediaType.geojson, MediaType.geotiff, MediaType.json, MediaType.zip,
                                            MediaType.html, MediaType.png)},
          "description": "The result file."},
    410: {"model": ErrorBody, "description": "The result was removed from the server after the job succeeded."},
}


@router.get("/{job_id}/result", summary="Download a job's main result", responses=_RESULT_RESPONSES,
            operation_id="job_result",
            response_class=Response)
def job_result(job_id: JobId, request: Request, state: StateDep,
               format: str | None = Query(None, pattern="^(geojson|geotiff)$",
                                          description="Contour jobs: geojson (default) or geotiff.")) -> Response:
    job = _get(state, job_id)
    names = MAIN_RESULT.get(job.kind, ())
    accept = request.headers.get("accept", "")
    want_tif = format == "geotiff" or (format is None and "image/tiff" in accept)
    name = names[1] if (job.kind == "contours" and want_tif) else (names[0] if names else "")
    return _file_response(_result_path(state, job, name, "job_id"))


@router.get("/{job_id}/files/{name:path}", summary="Download one result file", responses=_RESULT_RESPONSES,
            response_class=Response)
def job_file(job_id: JobId, name: Annotated[FileName, PathParam(description="A file of the job's listing.")],
             state: StateDep) -> Response:
    return _file_response(_result_path(state, _get(state, job_id), name))


@router.post("/{job_id}/cancel", response_model=JobInfo, dependencies=WRITE, summary="Cancel a queued or running job",
             operation_id="cancel_job")
def cancel_job(job_id: JobId, request: Request, state: StateDep) -> JobInfo:
    job = _get(state, job_id)
    if job.done:
        raise ApiError(409, f"job_id: job {job.id} is already {job.status}", field="job_id")
    job = state.jobs.request_cancel(job_id) or job
    return job_info(request, job)


@router.delete("/{job_id}", status_code=204, dependencies=WRITE, response_class=Response, operation_id="delete_job",
               summary="Delete a finished job and its files")
def delete_job(job_id: JobId, state: StateDep) -> Response:
    job = _get(state, job_id)
    if not job.done:
        raise ApiError(409, f"job_id: job {job.id} is {job.status}; cancel it first", field="job_id")
    state.jobs.delete(job_id)
    return Response(status_code=204)
