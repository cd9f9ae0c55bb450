"""The agent's refusal lines stay whole lines with several workers refusing at once
(issue 27's recheck: two workers' lines were seen run together on the agent's stderr,
"... 38 so farmm-beagle-agent: refused a command request: ...")."""

from __future__ import annotations

from mm_beagle.link.agent_requests import Refusals


class Writes:
    """A stream that keeps each write call apart (a thread switch may fall between two)."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def write(self, text: str) -> int:
        self.calls.append(text)
        return len(text)

    def flush(self) -> None:
        pass


def test_a_refusal_is_written_as_one_whole_line_in_one_call():
    out = Writes()
    r = Refusals(stream=out)
    r.refuse("history", "size", "history request of 60000 bytes is too large (limit 4096)")
    r.refuse("command", "json", "command request is not JSON")
    assert out.calls == [
        "mm-beagle-agent: refused a history request: history request of 60000 bytes is too "
        "large (limit 4096); 1 so far\n",
        "mm-beagle-agent: refused a command request: command request is not JSON; 2 so far\n",
    ]
    assert r.status()["requests_refused"] == 2
