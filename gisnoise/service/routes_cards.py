"""Model cards: list, get, upload (validated, versioned), delete."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Path, Query, Request, Response

from gisnoise.model import cards as gcards
from gisnoise.service.cardstore import StoredCard
from gisnoise.service.deps import WRITE, State, StateDep
from gisnoise.service.models import CardDocument, CardInfo, CardList, CardVersions, MediaType, PhaseName, SafeId
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse

router = APIRouter(prefix="/cards", tags=["cards"])

CardId = Annotated[SafeId, Path(description="Card id.")]


def _info(request: Request, state: State, stored: StoredCard) -> CardInfo:
    c = stored.card
    return CardInfo(
        id=c.id, version=stored.version, versions=state.cards.versions(c.id), vehicle=c.vehicle, phase=c.phase,
        phases=list(c.served_phases), ansatz=c.ansatz, reference_power_w=c.reference_power_w,
        has_covariance=c.covariance is not None, notes=c.notes, url=str(request.url_for("get_card", card_id=c.id)),
    )


def _card_response(stored: StoredCard, status_code: int = 200) -> Response:
    return Response(stored.path.read_bytes(), status_code=status_code, media_type=MediaType.json.value,
                    headers={"X-Card-Version": str(stored.version), "ETag": f'"{stored.card.id}@{stored.version}"'})


@router.get("", response_model=CardList, summary="List the cards (latest versions)")
def list_cards(request: Request, state: StateDep,
               phase: Annotated[PhaseName | None, Query(description="Only cards serving this phase.")] = None
               ) -> CardList:
    out = []
    for cid in state.cards.ids():
        try:
            stored = state.cards.get(cid)
        except gcards.CardError:
            continue  # an unreadable file in the store is skipped, not served
        if phase is None or phase in stored.card.served_phases:
            out.append(_info(request, state, stored))
    return CardList(cards=out)


@router.get("/{card_id}", response_model=CardDocument, summary="Get a card (latest version unless one is named)",
            responses={200: {"content": {MediaType.json.value: {}},
                             "headers": {"X-Card-Version": {"schema": {"type": "integer"}}}}})
def get_card(card_id: CardId, state: StateDep,
             version: int | None = Query(None, ge=1, description="Version; default the latest.")) -> Response:
    return _card_response(state.cards.get(card_id, version))


@router.get("/{card_id}/versions", response_model=CardVersions, summary="The versions of a card")
def card_versions(card_id: CardId, state: StateDep) -> CardVersions:
    vs = state.cards.versions(card_id)
    if not vs:
        state.cards.get(card_id)  # raises the 404
    return CardVersions(id=card_id, versions=vs)


@router.post("", response_model=CardInfo, status_code=201, dependencies=WRITE,
             summary="Upload a card (validated; never overwrites)",
             responses={200: {"model": CardInfo, "description": "Identical to the latest version: nothing stored."},
                        409: {"description": "A different card with this id exists (use new_version=true)."}})
def upload_card(request: Request, doc: Annotated[CardDocument, Body()], state: StateDep,
                new_version: bool = Query(False, description="Store as the next version when the id exists.")
                ) -> JSONResponse:
    card = gcards.from_dict(doc.model_dump(by_alias=True, exclude_unset=False), source="card")
    stored, created = state.cards.put(card, new_version=new_version)
    info = _info(request, state, stored)
    return JSONResponse(info.model_dump(), status_code=201 if created else 200,
                        headers={"Location": info.url + f"?version={stored.version}"})


@router.delete("/{card_id}", status_code=204, dependencies=WRITE, summary="Delete a card (all versions or one)",
               response_class=Response)
def delete_card(card_id: CardId, state: StateDep,
                version: int | None = Query(None, ge=1, description="Only this version.")) -> Response:
    state.cards.delete(card_id, version)
    return Response(status_code=204)
