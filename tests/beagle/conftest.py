"""Fixtures the tests of mm-beagle as a real process share: a client, and the node itself.

A module says how its node runs with a module attribute ``BEAGLE_NODE`` (read through
``request.module``, like tests/monitor's ``beagle_node`` reads ``BEAGLE_PARAMS``)::

    BEAGLE_NODE = {
        "namespace": "/chips",  # the node's namespace ("" unless set): the client's too
        "sim": {...},     # parameters of the backend:=sim node (its emulated sensors included)
        "agent": {...},   # options of the mm-beagle-agent serving the same emulated sensors
        "remote": {...},  # parameters of the backend:=remote node on that agent's link
    }
"""

from __future__ import annotations

import os

import pytest
from fakes import scaled


def _setup(request) -> dict:
    """The requesting module's ``BEAGLE_NODE`` (empty: sim defaults, default namespace)."""
    return getattr(request.module, "BEAGLE_NODE", {})


@pytest.fixture(scope="module")
def client(request):
    """One BeagleClient per test module (node ``mm_<module>_client``), talking to the
    mm-beagle in the module's namespace; closed after the module."""
    from mm_beagle.tools.harness import BeagleClient

    name = request.module.__name__.rpartition(".")[2]
    namespace = _setup(request).get("namespace", "")
    c = BeagleClient(f"mm_{name}_client", namespace=f"{namespace}/mm_beagle")
    yield c
    c.close()


@pytest.fixture(scope="module", params=["sim", "remote"])
def node(request, client, tmp_path_factory):
    """The module's mm-beagle, once per backend, its services up; yields (process, log path).

    ``sim``: the node polls its own emulated sensors (``BEAGLE_NODE["sim"]``).
    ``remote``: an mm-beagle-agent process polls them (``["agent"]``, on a free loopback
    port) and the node reads it in backend:=remote (``["remote"]``). Both stop after the
    module; a node whose services do not come up fails with its log.
    """
    from mm_beagle.tools.harness import agent_process, beagle_process, free_port

    setup = _setup(request)
    namespace = setup.get("namespace", "")
    logs = tmp_path_factory.mktemp("node")
    log = logs / "mm_beagle.log"
    env = dict(os.environ)

    def up(proc):
        assert client.wait(scaled(60)), f"services did not come up; log:\n{log.read_text()}"
        return proc, log

    if request.param == "sim":
        params = {"backend": "sim", **setup.get("sim", {})}
        with beagle_process(params, env=env, log_path=str(log), namespace=namespace) as proc:
            yield up(proc)
        return
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agent_opts = {"backend": "sim", "listen": [endpoint], **setup.get("agent", {})}
    params = {"backend": "remote", "agent": endpoint, **setup.get("remote", {})}
    with (
        agent_process(agent_opts, log_path=str(logs / "agent.log")),
        beagle_process(params, env=env, log_path=str(log), namespace=namespace) as proc,
    ):
        yield up(proc)
