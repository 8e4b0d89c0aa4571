"""Live studies: people (or scripted participants) drive study episodes through a web server.

`trustroute live CONFIG` serves one study (docs/live_studies.md): auth.py authenticates every
request and websocket, protocol.py validates every message, session.py runs each participant's
trials, worker.py runs one episode in its own SUMO process with the study's episode code,
server.py owns the study directory, app.py is the FastAPI application, scripted.py a synthetic
participant that speaks the same websocket protocol.
"""
