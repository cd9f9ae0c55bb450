"""``python -m pln2033.pmw33xx``: the poll budget table of docs/sensors.md (top speed, top CPI)."""

from __future__ import annotations

from .driver import PMW3360_INFO, PMW3389_INFO, poll_budget


def main() -> None:
    print("chip     rate_hz  counts/poll  headroom  min_rate_hz  hold_us  tSRAD_share  hold_share")
    for info in (PMW3360_INFO, PMW3389_INFO):
        for rate in (1000, 500, 250):
            b = poll_budget(info, rate)
            print(
                f"{b.chip:8s} {rate:7d} {b.counts_per_poll:12.0f} {b.headroom:9.1f} "
                f"{b.min_rate_hz:12.1f} {b.hold_us:8.1f} {b.delay_share:11.1%} {b.hold_share:11.1%}"
            )


if __name__ == "__main__":
    main()
