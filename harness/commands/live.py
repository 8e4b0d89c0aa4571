"""`trustroute live`: serve one study to people (docs/live_studies.md).

The study config is `trustroute study`'s, with engine = "live". The server binds 127.0.0.1 by
default (another host: a warning on stderr; so is an HTTPS --public-origin without
--secure-cookies), takes the port before it writes or prints anything
(a port in use: one line, exit 2), prints the experimenter's console address for each address it
is reachable at (carrying the token once) and the token, and serves until interrupted; a second
server on the same study directory is refused (exit 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from trustroute.core import defaults, ranges
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import Checked

if TYPE_CHECKING:
    from trustroute.harness.live.server import ServerOptions


@dataclass(frozen=True)
class ServeOptions:
    """`trustroute live`'s options, in the order --help lists them."""

    host: str = option("--host", default="127.0.0.1", show_default=True,
                       help="Address to bind (another than 127.0.0.1 exposes the study to the network).")
    port: int = option("--port", type=Checked(ranges.PORT), default=8765, show_default=True,
                       help="Port to bind.")
    out: str | None = option("--out", type=click.Path(), default=None,
                             help="Study DIRECTORY (default: the config's output, else studies/<name>).")
    pace: float = option("--pace", type=Checked(ranges.PACE), default=defaults.LIVE_PACE,
                         show_default=True, help="Simulated seconds per wall-clock second (1: real time).")
    resume_within: float = option(
        "--resume-within", type=Checked(ranges.RESUME_WITHIN), default=defaults.LIVE_RESUME_WITHIN,
        show_default=True, help="Seconds a disconnected participant has to resume; after that the "
        "episode is incomplete and runs again at the end of their plan.")
    warm_up: bool = option("--warm-up/--no-warm-up", default=defaults.LIVE_WARM_UP, show_default=True,
                           help="A warm-up drive before each participant's trials (not part of the dataset).")
    secure_cookies: bool = option(
        "--secure-cookies", is_flag=True,
        help="Mark the cookies Secure (the study is served over HTTPS, e.g. behind a TLS proxy).")
    consent_path: str | None = option(
        "--consent", type=click.Path(), default=None,
        help="Text FILE shown to participants before they consent (default: a short generic text).")
    public_origins: tuple[str, ...] = option(
        "--public-origin", multiple=True, metavar="URL",
        help="The address participants reach the study at behind a reverse proxy (e.g. "
        "https://study.example.org); repeatable. Pages from any other origin, and requests "
        "addressed to any other host, are refused.")
    connections_per_address: int | None = option(
        "--connections-per-address", type=Checked(ranges.CONNECTIONS_PER_ADDRESS), default=None,
        help="Open connections one address may hold, this machine's included (default: two "
        "stations' worth for another machine's address, no cap for this machine's). Raise it where "
        "stations reach the study through one address: a NAT, or a reverse proxy on another host.")

    def server_options(self) -> ServerOptions:
        """The station's options, the public origins checked."""
        from trustroute.harness.live.server import ServerOptions

        return ServerOptions(pace=self.pace, resume_within=self.resume_within, warm_up=self.warm_up,
                             secure_cookies=self.secure_cookies,
                             public_origins=checked_origins(self.public_origins),
                             connections_per_address=self.connections_per_address)

    def consent(self) -> str:
        """The consent text: --consent's file, else the generic one."""
        from trustroute.harness.live.server import DEFAULT_CONSENT

        if self.consent_path is None:
            return DEFAULT_CONSENT
        from trustroute.core.validation import read_text

        return read_text(self.consent_path, self.consent_path, "the consent text",
                         "pass a readable UTF-8 text file")


@click.command("live")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@takes(options=ServeOptions)
def live(config_path: str, options: ServeOptions) -> None:
    """Serve the study described by CONFIG (engine = "live") to participants in their browsers."""
    from trustroute.harness.live.app import serve
    from trustroute.harness.live.guard import bind
    from trustroute.harness.live.server import LiveStudy
    from trustroute.harness.study.config import load_study_config, study_directory

    config = load_study_config(config_path)
    consent = options.consent()
    server_options = options.server_options()
    study_dir = Path(study_directory(config, options.out))
    host, origins = options.host, server_options.public_origins
    sock = bind(host, options.port)   # before anything is printed or written: a port in use leaves nothing
    try:
        with LiveStudy(config, study_dir, server_options, consent) as study:
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
    """The study, its console address(es) (one login token: the link works once, at any of them)
    and the experimenter token (for scripts); a warning on stderr when the study is reachable from
    other computers, and one for each HTTPS public origin while the cookies are not Secure."""
    from trustroute.harness.live.guard import is_loopback, normal_origin, shown_host, usable_addresses

    login = study.login_token
    click.echo(f"live study {study.config.name}: {study.study_dir}")
    if not is_loopback(host):
        click.echo(f"warning: --host {host} serves this study to every computer that reaches this one's "
                   f"network at port {port}; use it on a lab network or behind an HTTPS proxy "
                   "(--secure-cookies, --public-origin)", err=True)
    for origin in public:
        if (normal_origin(origin) or "").startswith("https://") and not study.options.secure_cookies:
            click.echo(f"warning: {origin} is HTTPS but the cookies are not marked Secure, so a browser also "
                       "sends them over plain HTTP; add --secure-cookies", err=True)
    for address in usable_addresses(host):
        click.echo(f"console: http://{shown_host(address)}:{port}/login?token={login}")
    for origin in public:
        click.echo(f"console: {origin.rstrip('/')}/login?token={login}")
    click.echo(f"experimenter token: {study.experimenter_token}")
