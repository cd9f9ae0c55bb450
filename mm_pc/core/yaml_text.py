"""Parse YAML text from a user's file with a one-line message for every way it can fail."""

from __future__ import annotations

import yaml

__all__ = ["parse_yaml", "yaml_problem"]


def yaml_problem(exc: BaseException) -> str:
    """One line for a PyYAML error (or the parser's RecursionError): what and where."""
    if isinstance(exc, RecursionError):
        return "nested too deeply (the YAML parser recurses once per level)"
    problem = getattr(exc, "problem", None) or getattr(exc, "context", None)
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    text = problem or (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    if mark is not None:
        text += f" (line {mark.line + 1}, column {mark.column + 1})"
    return f"not valid YAML: {text}"


def parse_yaml(text: str, loader: type = yaml.SafeLoader) -> object:
    """``yaml.load(text, loader)`` (safe by default); ValueError with :func:`yaml_problem`'s
    line on bad input."""
    try:
        return yaml.load(text, Loader=loader)
    except (yaml.YAMLError, RecursionError) as e:
        raise ValueError(yaml_problem(e)) from None
