"""What the service stores and lists: a saved corridor (a plan request with an id)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from .request import PlanRequest

__all__ = ["CorridorRecord"]


class CorridorRecord(BaseModel):
    id: str = Field(description="Corridor id (uuid4 hex)")
    name: str | None = Field(description="Corridor name")
    created: str = Field(description="Creation time, ISO-8601 UTC")
    updated: str = Field(description="Last update time, ISO-8601 UTC")
    request: PlanRequest = Field(description="The plan request (same shape as the body of POST /v1/plan; "
                                 "m, m, rad, s)")
