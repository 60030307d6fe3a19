"""`voicectl router`: a Zenoh router that every voicectl service connects to."""

from __future__ import annotations

import argparse
import logging
import sys

import zenoh

from voicectl.shared.bus import BusOptions
from voicectl.shared.errors import BusError, ServiceError
from voicectl.shared.process import Service, add_bus_arguments, bus_options, run_service, serve

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl router", description=__doc__)
    add_bus_arguments(parser, router=True)
    return parser.parse_args(argv)


class Router(Service):
    """A Zenoh session in router mode: `start()` opens it listening, `stop()` closes it;
    its work is all inside Zenoh, so `run()` is the default (nothing until the stop)."""

    def __init__(self, options: BusOptions) -> None:
        self._options = options
        self._session: zenoh.Session | None = None

    async def start(self) -> None:
        options = self._options
        listen = ", ".join(options.listen) or f"the endpoints of {options.config_file}"
        try:
            # Listening only, never waiting for a peer: quick enough for the loop.
            self._session = zenoh.open(options.zenoh_config())
        except (zenoh.ZError, BusError) as exc:
            reason = str(exc).split(" at /", 1)[0]
            raise ServiceError(f"cannot listen on {listen}: {reason}") from exc
        _LOGGER.info("router listening on %s", listen)

    async def stop(self) -> None:
        if self._session is not None:
            self._session.close()


async def main(args: argparse.Namespace) -> None:
    await serve(Router(bus_options(args, router=True)))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl router", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
