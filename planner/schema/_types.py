"""Field types shared by the request and result models.

Numbers are finite floats; vectors and point lists are validated as JSON lists (so the
OpenAPI schema shows their lengths) and handed to the planner as numpy arrays, which
serialise back to lists.
"""

from __future__ import annotations

from typing import Annotated, Any, LiteralString, cast

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, GetPydanticSchema
from pydantic_core import PydanticCustomError, core_schema

from .limits import MAX_COORDINATE, MAX_PENALTY

__all__ = ["Finite", "Count", "Coordinate", "Strict", "fail", "Pair", "Triple", "Vec2", "Vec3", "Points2", "Rows3",
           "Rows",
           "FloatArray", "Point2", "Pose3", "PointPair", "PoseTriple", "Penalty3", "array_of"]

#: a finite JSON number (an integer is a number; true, false and "1.5" are not)
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
#: a count: a JSON integer (not 2.0, true or "2")
Count = Annotated[int, Field(strict=True)]
#: a coordinate of a request: a position or length in m or an angle in rad, |value| <= MAX_COORDINATE
Coordinate = Annotated[float, Field(allow_inf_nan=False, strict=True, ge=-MAX_COORDINATE, le=MAX_COORDINATE)]


def array_of(inner: Any, **constraints: Any) -> GetPydanticSchema:
    """A field validated as the JSON type ``inner`` (with list ``constraints`` such as
    ``min_length``), held as a float ``numpy.ndarray``, serialised as lists again."""

    def get_schema(_tp: Any, handler: Any) -> core_schema.CoreSchema:
        schema = cast(core_schema.CoreSchema, handler.generate_schema(inner))
        if constraints:
            schema = cast(core_schema.CoreSchema, {**schema, **constraints})
        return core_schema.no_info_after_validator_function(
            _to_array, schema,
            serialization=core_schema.plain_serializer_function_ser_schema(_to_list, return_schema=schema))

    return GetPydanticSchema(get_schema)


def _to_array(value: Any) -> np.ndarray:
    return np.asarray(value, dtype=float)


def _to_list(value: Any) -> Any:
    return np.asarray(value).tolist()


#: [x, y] as JSON
Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]
#: [x, y, psi] as JSON
Triple = Annotated[list[Finite], Field(min_length=3, max_length=3)]

#: [x, y] of a request as JSON, each |value| <= MAX_COORDINATE
PointPair = Annotated[list[Coordinate], Field(min_length=2, max_length=2)]
#: [x, y, psi] of a request as JSON, each |value| <= MAX_COORDINATE
PoseTriple = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]
#: a request's [x, y] in m (or an angle range [min, max] in rad), |value| <= MAX_COORDINATE
Point2 = Annotated[np.ndarray, array_of(PointPair)]
#: a request's [x, y, psi] in m, m, rad, |value| <= MAX_COORDINATE
Pose3 = Annotated[np.ndarray, array_of(PoseTriple)]
#: a diagonal penalty (three weights), each in [0, MAX_PENALTY]
Penalty3 = Annotated[np.ndarray, array_of(Annotated[list[Annotated[float, Field(allow_inf_nan=False, strict=True,
                                                                                  ge=0, le=MAX_PENALTY)]],
                                                    Field(min_length=3, max_length=3)])]

#: [x, y] in m
Vec2 = Annotated[np.ndarray, array_of(list[Finite], min_length=2, max_length=2)]
#: [x, y, psi] in m, m, rad
Vec3 = Annotated[np.ndarray, array_of(list[Finite], min_length=3, max_length=3)]
#: a list of [x, y] points in m
Points2 = Annotated[np.ndarray, array_of(list[Pair])]
#: rows of [x, y, psi] (one per sample)
Rows3 = Annotated[np.ndarray, array_of(list[Triple])]
#: rows of numbers (one row per sample, one column per drive or axis)
Rows = Annotated[np.ndarray, array_of(list[list[float]])]
#: a flat list of numbers
FloatArray = Annotated[np.ndarray, array_of(list[float])]


class Strict(BaseModel):
    """Unknown fields are errors (a typo must not be ignored)."""

    model_config = ConfigDict(extra="forbid")


def fail(message: str, field: str | None = None, code: str = "invalid_input") -> PydanticCustomError:
    """A validation error with a finished ``message``; ``field`` is a path below the
    validated model (see :mod:`planner.schema.errors`), ``code`` the error code."""
    return PydanticCustomError(cast(LiteralString, code), cast(LiteralString, message),
                               {"field": field} if field else None)
