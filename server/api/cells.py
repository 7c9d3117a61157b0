"""Cells: the built-in simulated cell and uploaded cell.json files (with `devices`: real ones)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from starlette.concurrency import run_in_threadpool

from robocal.server.acquisition import cells
from robocal.server.formats.cell_json import Cell, cell_to_json

from .deps import Authorized, SettingsDep
from .schemas import CellPublic

router = APIRouter(prefix="/cells", tags=["cells"])
JSON_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {
                # the model the upload is validated with (CellPublic puts it in the components)
                "schema": {"$ref": "#/components/schemas/CellDoc"}
            }
        },
    }
}


@router.get("")
def list_cells(settings: SettingsDep) -> list[str]:
    """The cell ids: `default` (the simulated IRB 2600 cell) and uploads."""
    return cells.list_cells(cells_dir=settings.cells_dir)


@router.get("/{cell_id}", response_model_exclude_none=True)
def get_cell(cell_id: str, settings: SettingsDep) -> CellPublic:
    """One cell as cell.json, and whether it is simulated."""
    return _public(cell_id, cells.load_cell(cells_dir=settings.cells_dir, cell_id=cell_id))


@router.post(
    "",
    status_code=201,
    dependencies=[Authorized],
    openapi_extra=JSON_BODY,
    response_model_exclude_none=True,
)
async def upload_cell(request: Request, settings: SettingsDep) -> CellPublic:
    """Validate a cell.json with the file's own model (CellDoc; read raw, so errors name its line
    and column) and keep it; a `devices` object makes it a real cell, whose campaigns drive the
    tracker and controller there."""
    text = (await request.body()).decode("utf-8", errors="replace")
    cell_id, cell = await run_in_threadpool(
        cells.save_cell, cells_dir=settings.cells_dir, text=text
    )
    return _public(cell_id, cell)


def _public(cell_id: str, cell: Cell) -> CellPublic:
    return CellPublic(id=cell_id, simulated=cell.simulated, cell=cell_to_json(cell))
