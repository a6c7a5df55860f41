"""What was read from a recording: its topics, their log times and deserialized messages."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Topic:
    name: str
    type: str
    count: int = 0
    log_ns: list = field(default_factory=list)
    msgs: list = field(default_factory=list)


@dataclass
class Recording:
    """What was read from a file: topics (with the requested messages) and format."""

    path: Path
    format: str
    topics: dict[str, Topic]
    start_ns: int | None
    end_ns: int | None
    truncated: str | None = None  # the reader's complaint, when reading stopped early
    read_messages: int = 0


def _reason(e: Exception) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) < 160 else text[:157] + "..."
