// The experimenter console: create participants, follow their progress, control episodes,
// download the study directory's files. Every call carries the HttpOnly experimenter cookie.
"use strict";

const $ = (id) => document.getElementById(id);

function showError(text) { if ($("error").textContent !== (text || "")) $("error").textContent = text || ""; }

// What a withdrawal did, in the words `trustroute withdraw` prints (the server's `line`): above all
// which packages exported before still hold the participant's data, to be replaced wherever they
// were shared. Kept until dismissed or the next action, so it is not missed.
function showNotice(text) {
  $("notice-text").textContent = text || "";
  $("notice").classList.toggle("hidden", !text);
}

// the server restarted (its console logins are new at every start), the login expired (unused for
// hours: auth.CONSOLE_IDLE_SECONDS) or the cookie is gone
const LOGGED_OUT = "This console is no longer logged in (the server was restarted, the login expired, or it is gone): "
  + "open the new console link the server printed, or make one with POST /api/login-link.";
const GONE = "The server does not answer (stopped?); the console tries again every second.";

async function call(method, path, body) {
  const options = { method, headers: {} };
  if (body !== undefined) {
    options.headers["content-type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  let response;
  try { response = await fetch(path, options); }
  catch { throw new Error(GONE); }
  const payload = await response.json().catch(() => ({}));
  if (response.status === 401 || response.status === 403) throw new Error(LOGGED_OUT);
  if (!response.ok) {
    const detail = payload.detail && payload.detail.detail ? payload.detail.detail : payload.detail;
    throw new Error(`${response.status}: ${detail || payload.code || "refused"}`);
  }
  return payload;
}

function cell(row, text) {
  const td = document.createElement("td");
  td.textContent = text === null || text === undefined ? "" : String(text);
  row.appendChild(td);
  return td;
}

function controlButton(participant, action) {
  const button = document.createElement("button");
  button.textContent = action;
  button.addEventListener("click", async () => {
    // an abort throws the drive away (it is run again): the experimenter confirms it, told which
    // drive it is in the row's words (the state's `trial_status`: "driving the warm-up")
    if (action === "abort") {
      const drive = button.closest("tr").cells[TRIAL_STATUS].textContent;
      if (!window.confirm(`Abort participant ${participant}'s drive (${drive})? It will be run again.`)) return;
    }
    showNotice("");
    try { await call("POST", `/api/participants/${participant}/control`, { action }); showError(""); }
    catch (error) { showError(error.message); }
    refresh();
  });
  return button;
}

function showLink(participant, link) {
  const box = $("created");
  box.textContent = `participant ${participant}: ${location.origin}${link}`;
  box.classList.remove("hidden");
}

// The server keeps only digests of tokens: a link is shown once. A new one revokes the old.
function linkButton(participant) {
  const button = document.createElement("button");
  button.textContent = "new link";
  button.addEventListener("click", async () => {
    if (!confirm(`A new link for participant ${participant}? Their current link and open station stop working.`)) return;
    showNotice("");
    try { const issued = await call("POST", `/api/participants/${participant}/link`); showLink(participant, issued.link); showError(""); }
    catch (error) { showError(error.message); }
    refresh();
  });
  return button;
}

// Withdrawal deletes the participant's data for good (audited in live/withdrawals.jsonl).
function withdrawButton(participant) {
  const button = document.createElement("button");
  button.textContent = "withdraw";
  button.addEventListener("click", async () => {
    if (!confirm(`Withdraw participant ${participant}? Every drive and answer of theirs is deleted from the study; this cannot be undone.`)) return;
    showNotice("");
    try {
      const done = await call("POST", `/api/participants/${participant}/withdraw`, { confirm: true });
      showNotice(done.line);
      showError("");
    }
    catch (error) { showError(error.message); }
    refresh();
  });
  return button;
}

// The buttons each console action has, in the cell it goes in (the episode's, the participant's).
const BUTTONS = { pause: controlButton, resume: controlButton, abort: controlButton, link: linkButton,
                  withdraw: withdrawButton };
const EPISODE = ["pause", "resume", "abort"];

// A participant who withdrew or declined has no progress to show: their row keeps its number,
// label and phase and says why in place of the rest. A withdrawal is final while the server runs
// (a readmission is `trustroute withdraw --readmit`, which needs the server stopped); one who
// declined can be asked again with a new link.
const NOTES = {
  withdrawn: "Withdrawn from the study: their drives and answers are deleted, so there is nothing to control.",
  declined: "Did not agree to take part: nothing of theirs is kept. A new link asks for their consent again.",
};
const KEPT = 3;   // the cells a noted row keeps: #, label, phase

// The table is refreshed every second in place: each participant's row (by its number) is made
// once with its cells, and each button once; only texts change, and the cells and buttons are laid
// out again only when the phase's note or the actions the server offers change (the state's
// `actions`: the server's one rule, harness/live/session.py CONSOLE_ACTIONS), so a button keeps
// the keyboard's focus.
const TEXTS = 10;   // the cells before the episode control and participant buttons
const TRIAL_STATUS = 3;   // the cell of `trial_status` among them
function texts(p) {
  return [p.participant, p.label, p.paused_by ? `${p.phase} (${p.paused_by})` : p.phase, p.trial_status,
          p.episode_id, p.mode, p.road, p.reports, p.takeovers, p.last_error];
}

function rowOf(body, participant) {
  const found = body.querySelector(`tr[data-participant="${participant}"]`);
  if (found) return found;
  const row = document.createElement("tr");
  row.dataset.participant = participant;
  const td = () => document.createElement("td");   // (placed in the row by `layOut`)
  row.parts = { texts: Array.from({ length: TEXTS }, td), episode: td(), participant: td(), note: td(),
                buttons: {} };
  row.parts.note.className = "row-note";
  body.appendChild(row);
  return row;
}

function button(row, action) {
  const made = row.parts.buttons;
  if (!made[action]) made[action] = BUTTONS[action](Number(row.dataset.participant), action);
  return made[action];
}

function layOut(row, p) {
  const { texts: cells, episode, participant, note } = row.parts;
  const offered = (actions) => actions.filter((action) => p.actions.includes(action)).map((a) => button(row, a));
  episode.replaceChildren(...offered(EPISODE));
  participant.replaceChildren(...offered(Object.keys(BUTTONS).filter((action) => !EPISODE.includes(action))));
  const noted = NOTES[p.phase];
  row.className = noted ? `noted ${p.phase}` : "";
  if (!noted) { row.replaceChildren(...cells, episode, participant); return; }
  note.textContent = noted;
  const ends = participant.childElementCount ? [participant] : [];
  note.colSpan = TEXTS + 2 - KEPT - ends.length;
  row.replaceChildren(...cells.slice(0, KEPT), note, ...ends);
}

async function refresh() {
  try {
    const { participants } = await call("GET", "/api/participants");
    if ([GONE, LOGGED_OUT].includes($("error").textContent)) showError("");   // answered again
    const body = $("participants");
    for (const p of participants) {
      const row = rowOf(body, p.participant);
      texts(p).forEach((text, i) => {
        const shown = text === null || text === undefined ? "" : String(text);
        if (row.parts.texts[i].textContent !== shown) row.parts.texts[i].textContent = shown;
      });
      const view = `${p.phase}:${p.actions.join(",")}`;
      if (row.dataset.view !== view) { row.dataset.view = view; layOut(row, p); }
    }
  } catch (error) { showError(error.message); }
}

async function listFiles() {
  try {
    const { files } = await call("GET", "/api/files");
    const list = $("files");
    list.replaceChildren();
    for (const file of files) {
      const item = document.createElement("li");
      const link = document.createElement("a");
      link.href = "/api/download/" + file.split("/").map(encodeURIComponent).join("/");
      link.textContent = file;
      item.appendChild(link);
      list.appendChild(item);
    }
  } catch (error) { showError(error.message); }
}

$("create").addEventListener("click", async () => {
  showNotice("");
  try {
    const created = await call("POST", "/api/participants", { label: $("label").value });
    showLink(created.participant, created.link);
    $("label").value = "";   // the next participant's label is typed afresh (a refused one is kept to correct)
    showError("");
    refresh();
  } catch (error) { showError(error.message); }
});
$("refresh-files").addEventListener("click", listFiles);
$("dismiss").addEventListener("click", () => showNotice(""));
refresh();
setInterval(refresh, 1000);
