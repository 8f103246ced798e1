"""docker-compose.yml: it parses, and every service runs a valid `sensornet` invocation."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from sensornet.sim.scenario import load_scenario, parse_overrides

from sensornet.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def compose():
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def test_services_are_the_world_and_three_peers(compose):
    assert set(compose["services"]) == {"world", "s1", "s2", "s3"}
    images = {s["image"] for s in compose["services"].values()}
    assert images == {"sensornet:latest"}  # one image for all
    assert (ROOT / "Dockerfile").is_file()


def test_every_command_is_a_valid_cli_invocation(compose):
    parser = build_parser()
    networks, run_ids = set(), set()
    for name, service in compose["services"].items():
        args = parser.parse_args(service["command"])  # argparse exits on an invalid command
        assert args.command == ("world" if name == "world" else "peer")
        networks.add(args.network)
        run_ids.add(args.run_id)
        scn = load_scenario(getattr(args, "scenario", "seed000"),
                            overrides=parse_overrides(args.set or []))
        if name != "world":
            assert args.name == name and args.name in scn.sensor_names
            assert "tcp/world:7447" in args.connect
        else:
            assert sorted(args.peers.split(",")) == ["s1", "s2", "s3"]
        assert args.out.startswith("/runs")
    assert len(networks) == 1 and len(run_ids) == 1  # one key space, one Rerun recording


def test_invalid_command_would_be_caught():
    with pytest.raises(SystemExit):
        build_parser().parse_args(["peer", "s1", "--no-such-flag"])


def _run_steps(dockerfile: str) -> list[str]:
    """The shell of every RUN instruction (continuation lines joined)."""
    text = dockerfile.replace("\\\n", " ")
    return [line.strip()[4:] for line in text.splitlines() if line.strip().startswith("RUN ")]


def test_dockerfile_fails_when_the_install_fails():
    steps = _run_steps((ROOT / "Dockerfile").read_text())
    installs = [s for s in steps if "pip install" in s]
    assert installs, steps
    for step in installs:
        top_level = re.sub(r"\([^()]*\)", "", step)  # `(... || true)` may only excuse itself
        assert "||" not in top_level and ";" not in top_level, step
        assert "sensornet --help" in step  # the installed command must run, or no image


def test_dockerfile_image_carries_no_sources_or_tests():
    text = (ROOT / "Dockerfile").read_text()
    final = text[text.rindex("\nFROM "):]
    assert "COPY --from=" in final
    assert not re.search(r"^COPY (?!--from)", final, re.M), final  # no sources in the image
    copies = [ln for ln in text.splitlines() if ln.startswith("COPY ")]
    assert not [ln for ln in copies if "tests" in ln or "benchmarks" in ln or " . " in ln]


def test_hosts_variant_is_a_router_the_world_and_hosts_that_hold_every_peer_once():
    """docker-compose.hosts.yml: a host per service, every process a client of the router;
    the hosts' peers are the world's, each in one host."""
    compose = yaml.safe_load((ROOT / "docker-compose.hosts.yml").read_text())
    services = compose["services"]
    assert {s["image"] for s in services.values()} == {"sensornet:latest"}
    parser = build_parser()
    args = {name: parser.parse_args(s["command"]) for name, s in services.items()}
    assert args.pop("router").command == "router"
    world = args.pop("world")
    assert world.command == "world" and "tcp/router:7447" in world.connect
    assert args and all(a.command == "host" for a in args.values())
    held = [p for a in args.values() for p in a.peers.split(",")]
    assert sorted(held) == sorted(world.peers.split(",")) and len(set(held)) == len(held)
    scn = load_scenario(world.scenario)
    assert set(held) <= set(scn.sensor_names)
    for name, a in args.items():
        assert a.name == name and a.connect == ["tcp/router:7447"], name
        assert "router" in services[name]["depends_on"]
        assert a.out.startswith("/runs")
    assert len({a.network for a in [world, *args.values()]}) == 1
    assert len({a.run_id for a in [world, *args.values()]}) == 1
