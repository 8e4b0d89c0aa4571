// A participant's link (/p/TOKEN): the token is claimed once (POST /api/claim), which puts a fresh
// token in the HttpOnly cookie and spends the one in this address, then the station replaces this
// page: the link left in the browser's history no longer opens the session.
"use strict";

async function claim() {
  const token = decodeURIComponent(location.pathname.split("/").pop());
  history.replaceState(null, "", "/p/");
  const response = await fetch("/api/claim", {
    method: "POST", headers: { "content-type": "application/json" }, body: JSON.stringify({ token }),
  });
  if (response.ok) {
    location.replace((await response.json()).next);
    return;
  }
  // 409: the browser is logged in to the console; the server's text says where to open the link
  document.getElementById("message").textContent = response.status === 403
    ? "This link has been used already (or was revoked). If this is your session, ask the experimenter for a new link."
    : response.status === 409 ? (await response.json()).detail.detail
      : `The session could not be opened (${response.status}).`;
}

claim();
