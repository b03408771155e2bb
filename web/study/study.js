// fewview 2AFC study page: joins (or resumes) a participant, shows the next pair, posts the
// answers. The server stores every answer before replying, so reloading loses nothing.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const KEY = "fewview-study-participant";
  let state = null;
  let busy = false;

  function showError(message) {
    const e = $("error");
    e.textContent = message;
    e.hidden = !message;
  }

  async function api(method, url, body) {
    const response = await fetch(url, {
      method,
      headers: body ? { "Content-Type": "application/json" } : {},
      body: body ? JSON.stringify(body) : undefined,
    });
    const data = await response.json().catch(() => ({ error: "bad reply from the server" }));
    if (!response.ok) {
      const err = new Error(data.error || response.statusText);
      err.status = response.status;
      throw err;
    }
    return data;
  }

  function mediaElement(side) {
    if (side.kind === "image") {
      const img = document.createElement("img");
      img.src = side.url;
      img.alt = "";
      return img;
    }
    const video = document.createElement("video");
    video.src = side.url;
    video.autoplay = true;
    video.loop = true;
    video.muted = true;
    video.playsInline = true;
    return video;
  }

  function answers() {
    const out = {};
    for (const q of state.questions) {
      const checked = document.querySelector(`input[name="${CSS.escape(q.id)}"]:checked`);
      if (!checked) return null;
      out[q.id] = checked.value;
    }
    return out;
  }

  function render(s) {
    state = s;
    localStorage.setItem(KEY, s.participant);
    $("title").textContent = s.title;
    $("progress").textContent = `${Math.min(s.answered + 1, s.total)} / ${s.total}`;
    if (s.done) {
      $("progress").textContent = `${s.total} / ${s.total}`;
      $("study").hidden = true;
      $("done").hidden = false;
      return;
    }
    $("done").hidden = true;
    $("study").hidden = false;
    $("study").dataset.trial = String(s.trial.index);
    for (const side of ["left", "right"]) {
      const box = $(`${side}-media`);
      box.replaceChildren(mediaElement(s.trial[side]));
    }
    const form = $("questions");
    form.replaceChildren();
    for (const q of s.questions) {
      const fs = document.createElement("fieldset");
      const legend = document.createElement("legend");
      legend.textContent = `${q.id}: ${q.text}`;
      fs.appendChild(legend);
      for (const side of ["left", "right"]) {
        const label = document.createElement("label");
        const input = document.createElement("input");
        input.type = "radio";
        input.name = q.id;
        input.value = side;
        input.addEventListener("change", () => { $("next").disabled = answers() === null; });
        label.append(input, ` ${side === "left" ? "Left" : "Right"}`);
        fs.appendChild(label);
      }
      form.appendChild(fs);
    }
    $("next").disabled = true;
  }

  async function submit() {
    const a = answers();
    if (!a || busy) return;
    busy = true;
    $("next").disabled = true;
    try {
      render(await api("POST", `/api/participants/${encodeURIComponent(state.participant)}/answers`, { index: state.trial.index, answers: a }));
      showError("");
    } catch (err) {
      showError(`Could not save the answer: ${err.message}`);
      // Out of order (another tab answered): reload the current state.
      if (err.status === 409) {
        try { render(await api("GET", `/api/participants/${encodeURIComponent(state.participant)}`)); } catch (_) { /* keep the message */ }
      } else {
        $("next").disabled = false;
      }
    } finally {
      busy = false;
    }
  }

  async function start() {
    const fromUrl = new URLSearchParams(location.search).get("participant");
    const stored = localStorage.getItem(KEY);
    const id = fromUrl || stored;
    try {
      render(await api("POST", "/api/participants", id ? { participant: id } : {}));
    } catch (err) {
      showError(`Could not start the study: ${err.message}`);
    }
  }

  $("next").addEventListener("click", submit);
  start();
})();
