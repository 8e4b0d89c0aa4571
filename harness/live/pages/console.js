// The experimenter console: create participants, follow their progress, control episodes,
// download the study directory's files. Every call carries the HttpOnly experimenter cookie.
"use strict";

const $ = (id) => document.getElementById(id);

function showError(text) { $("error").textContent = text || ""; }

async function call(method, path, body) {
  const options = { method, headers: {} };
  if (body !== undefined) {
    options.headers["content-type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  const response = await fetch(path, options);
  const payload = await response.json().catch(() => ({}));
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

function controlButton(td, participant, action) {
  const button = document.createElement("button");
  button.textContent = action;
  button.addEventListener("click", async () => {
    // an abort throws the trial's drive away (it is run again): the experimenter confirms it
    if (action === "abort" && !window.confirm(`Abort participant ${participant}'s trial? It will be run again.`)) return;
    try { await call("POST", `/api/participants/${participant}/control`, { action }); showError(""); }
    catch (error) { showError(error.message); }
    refresh();
  });
  td.appendChild(button);
}

async function refresh() {
  try {
    const { participants } = await call("GET", "/api/participants");
    const body = $("participants");
    body.replaceChildren();
    for (const p of participants) {
      const row = document.createElement("tr");
      row.dataset.participant = p.participant;
      cell(row, p.participant); cell(row, p.label);
      cell(row, p.paused_by ? `${p.phase} (${p.paused_by})` : p.phase);
      cell(row, `${p.trial} of ${p.trials}`); cell(row, p.episode_id); cell(row, p.mode);
      cell(row, p.road); cell(row, p.reports); cell(row, p.takeovers); cell(row, p.last_error);
      const controls = cell(row, "");
      for (const action of ["pause", "resume", "abort"]) controlButton(controls, p.participant, action);
      body.appendChild(row);
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
  try {
    const created = await call("POST", "/api/participants", { label: $("label").value });
    const box = $("created");
    box.textContent = `participant ${created.participant}: ${location.origin}${created.link}`;
    box.classList.remove("hidden");
    showError("");
    refresh();
  } catch (error) { showError(error.message); }
});
$("refresh-files").addEventListener("click", listFiles);
refresh();
setInterval(refresh, 1000);
