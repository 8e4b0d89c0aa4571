"""`trustroute live`: serve one study to people (docs/live_studies.md).

The study config is `trustroute study`'s, with engine = "live". The server binds 127.0.0.1 by
default, prints the experimenter's console address (carrying the token once) and the token, and
serves until interrupted; a second server on the same study directory is refused (exit 2).
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
def live(config_path: str, host: str, port: int, out: str | None, pace: float, resume_within: float,
         warm_up: bool, secure_cookies: bool, consent_path: str | None) -> None:
    """Serve the study described by CONFIG (engine = "live") to participants in their browsers."""
    from trustroute.harness.live.app import serve
    from trustroute.harness.live.server import DEFAULT_CONSENT, LiveStudy, ServerOptions
    from trustroute.harness.study.config import load_study_config, study_directory

    config = load_study_config(config_path)
    consent = DEFAULT_CONSENT
    if consent_path is not None:
        from trustroute.core.validation import read_text

        consent = read_text(consent_path, consent_path, "the consent text", "pass a readable UTF-8 text file")
    study_dir = Path(study_directory(config, out))
    options = ServerOptions(pace=pace, resume_within=resume_within, warm_up=warm_up,
                            secure_cookies=secure_cookies)
    with LiveStudy(config, study_dir, options, consent) as study:
        def announce() -> None:
            shown = host if ":" not in host else f"[{host}]"
            click.echo(f"live study {config.name}: {study.study_dir}")
            click.echo(f"console: http://{shown}:{port}/login?token={study.experimenter_token}")
            click.echo(f"experimenter token: {study.experimenter_token}")

        serve(study, host, port, on_ready=announce)
