"""`trustroute live`: serve one study to people (docs/live_studies.md).

The study config is `trustroute study`'s, with engine = "live". The server binds 127.0.0.1 by
default (another host: a warning on stderr), takes the port before it writes or prints anything
(a port in use: one line, exit 2), prints the experimenter's console address for each address it
is reachable at (carrying the token once) and the token, and serves until interrupted; a second
server on the same study directory is refused (exit 2).
"""

from __future__ import annotations

from pathlib import Path

import click

from trustroute.harness.commands.options import FiniteFloat, bounded_int


@click.command("live")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to bind (another than 127.0.0.1 exposes the study to the network).")
@click.option("--port", type=bounded_int(0, 65535), default=8765, show_default=True, help="Port to bind.")
@click.option("--out", "out", type=click.Path(), default=None,
              help="Study DIRECTORY (default: the config's output, else studies/<name>).")
@click.option("--pace", type=FiniteFloat(0.0, 10_000.0, open_minimum=True), default=1.0, show_default=True,
              help="Simulated seconds per wall-clock second (1: real time).")
@click.option("--resume-within", type=FiniteFloat(0.0, 86_400.0, open_minimum=True), default=120.0,
              show_default=True, help="Seconds a disconnected participant has to resume; after that the "
              "episode is incomplete and runs again at the end of their plan.")
@click.option("--warm-up/--no-warm-up", default=True, show_default=True,
              help="A warm-up drive before each participant's trials (not part of the dataset).")
@click.option("--secure-cookies", is_flag=True,
              help="Mark the cookies Secure (the study is served over HTTPS, e.g. behind a TLS proxy).")
@click.option("--consent", "consent_path", type=click.Path(), default=None,
              help="Text FILE shown to participants before they consent (default: a short generic text).")
@click.option("--public-origin", "public_origins", multiple=True, metavar="URL",
              help="The address participants reach the study at behind a reverse proxy (e.g. "
              "https://study.example.org); repeatable. Pages from any other origin are refused.")
def live(config_path: str, host: str, port: int, out: str | None, pace: float, resume_within: float,
         warm_up: bool, secure_cookies: bool, consent_path: str | None,
         public_origins: tuple[str, ...]) -> None:
    """Serve the study described by CONFIG (engine = "live") to participants in their browsers."""
    from trustroute.harness.live.app import serve
    from trustroute.harness.live.guard import bind
    from trustroute.harness.live.server import DEFAULT_CONSENT, LiveStudy, ServerOptions
    from trustroute.harness.study.config import load_study_config, study_directory

    config = load_study_config(config_path)
    consent = DEFAULT_CONSENT
    if consent_path is not None:
        from trustroute.core.validation import read_text

        consent = read_text(consent_path, consent_path, "the consent text", "pass a readable UTF-8 text file")
    origins = checked_origins(public_origins)
    study_dir = Path(study_directory(config, out))
    options = ServerOptions(pace=pace, resume_within=resume_within, warm_up=warm_up,
                            secure_cookies=secure_cookies, public_origins=origins)
    sock = bind(host, port)   # before anything is printed or written: a port in use leaves nothing
    try:
        with LiveStudy(config, study_dir, options, consent) as study:
            serve(study, sock, on_ready=lambda: announce(study, host, sock.getsockname()[1], origins))
    finally:
        sock.close()


def checked_origins(origins: tuple[str, ...]) -> tuple[str, ...]:
    from trustroute.core.errors import InputError
    from trustroute.harness.live.guard import normal_origin

    for origin in origins:
        if normal_origin(origin) is None:
            raise InputError("--public-origin", origin, "not an http(s) origin",
                             "give scheme://host[:port], e.g. https://study.example.org")
    return origins


def announce(study, host: str, port: int, public: tuple[str, ...]) -> None:
    """The study, its console address(es) and the experimenter token; a warning on stderr when the
    study is reachable from other computers."""
    from trustroute.harness.live.guard import is_loopback, shown_host, usable_addresses

    token = study.experimenter_token
    click.echo(f"live study {study.config.name}: {study.study_dir}")
    if not is_loopback(host):
        click.echo(f"warning: --host {host} serves this study to every computer that reaches this one's "
                   f"network at port {port}; use it on a lab network or behind an HTTPS proxy "
                   "(--secure-cookies, --public-origin)", err=True)
    for address in usable_addresses(host):
        click.echo(f"console: http://{shown_host(address)}:{port}/login?token={token}")
    for origin in public:
        click.echo(f"console: {origin.rstrip('/')}/login?token={token}")
    click.echo(f"experimenter token: {token}")
