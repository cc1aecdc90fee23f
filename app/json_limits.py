"""Which limit a JSON body hit, in words (issue 21): a body nested 500 000 deep, or a number of
5 000 digits, is refused naming that limit rather than as "not valid JSON".

Two parsers read bodies: FastAPI's (``json.loads``, for the request models: its nesting is
bounded by Python's recursion limit, an integer by ``sys.get_int_max_str_digits()``) and
orjson (batches: 1024 levels, numbers within a double).
"""

from __future__ import annotations

import sys

__all__ = ["body_error_text", "json_error_text"]

#: nesting of a plan request: the request, settings or a layout, obstacles, a polygon, a point
REQUEST_DEPTH = 6


def body_error_text(cause: BaseException | None) -> str:
    """The message of a JSON body FastAPI could not parse, from the parser's exception."""
    if isinstance(cause, RecursionError):
        return (f"body is not accepted: its JSON nests arrays and objects deeper than the parser's limit (about "
                f"{sys.getrecursionlimit()} levels, Python's recursion limit; a plan request has at most "
                f"{REQUEST_DEPTH})")
    if isinstance(cause, ValueError) and "digits" in str(cause):
        return (f"body is not accepted: a number in its JSON has more than {sys.get_int_max_str_digits()} digits, "
                "the parser's limit for an integer")
    return "body is not valid JSON (it must be UTF-8 text)"


def json_error_text(exc: Exception) -> str:
    """orjson's error message, with the limit named when one was hit."""
    text = str(exc)
    if text.startswith("depth limit exceeded"):
        return (f"arrays and objects nested deeper than the parser's limit of 1024 levels (a plan request has at "
                f"most {REQUEST_DEPTH}) ({text})")
    if "infinity when parsed as double" in text:
        return f"a number larger than the parser's limit (about 1.8e308, a double) ({text})"
    return text
