// End-to-end test of the study page, driven by crates/cli/tests/study_e2e.rs.
// Environment: STUDY_URL (server base URL), STUDY_RESULT (JSON file to write), CHROMIUM
// (browser binary), SIMULATED (number of concurrent API participants), MEDIA (`img`, the
// default, or `video`: what each side must show), MIN_TOTAL (fewest comparisons expected, 3 by
// default). Needs playwright-core
// (scripts/setup.sh installs it into .cache/browser; run with NODE_PATH pointing there).
"use strict";
const fs = require("fs");
const os = require("os");
const path = require("path");
const { chromium } = require("playwright-core");

const base = process.env.STUDY_URL;
const resultPath = process.env.STUDY_RESULT;
const simulated = Number(process.env.SIMULATED || "24");
const media = process.env.MEDIA || "img";
const minTotal = Number(process.env.MIN_TOTAL || "3");

function check(cond, message) {
  if (!cond) throw new Error(message);
}

async function json(method, url, body, raw) {
  const r = await fetch(base + url, {
    method,
    headers: { "Content-Type": "application/json" },
    body: raw !== undefined ? raw : body === undefined ? undefined : JSON.stringify(body),
  });
  return { status: r.status, body: await r.json() };
}

// One participant in the browser: answers half, reloads, checks nothing was lost, finishes.
async function browserSession() {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "fewview-chromium-"));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
  const page = context.pages()[0] || (await context.newPage());
  const participant = "browser-1";
  const choices = [];
  try {
    await page.goto(`${base}/?participant=${participant}`);
    await page.waitForSelector("#study:not([hidden])");
    const total = Number((await page.textContent("#progress")).split("/")[1]);
    check(total >= minTotal, `total ${total}`);
    const questions = await page.$$eval("fieldset legend", (ls) => ls.map((l) => l.textContent));
    check(questions.length === 2 && questions[0].startsWith("Q1: Which video shows more natural color transitions"), `questions ${questions}`);
    const answerOne = async (k) => {
      const progress = (await page.textContent("#progress")).trim();
      check(progress === `${k + 1} / ${total}`, `progress shows ${progress}, expected ${k + 1} / ${total}`);
      const index = Number(await page.getAttribute("#study", "data-trial"));
      // Both sides show their media, loaded from the server: an image decoded, or a video
      // element whose file the server delivers as a video.
      for (const side of ["left", "right"]) {
        if (media === "video") {
          await page.waitForFunction((s) => { const v = document.querySelector(`#${s}-media video`); return v && v.src; }, side);
          const served = await page.evaluate(async (s) => {
            const r = await fetch(document.querySelector(`#${s}-media video`).src);
            return `${r.status} ${r.headers.get("content-type")} ${(await r.arrayBuffer()).byteLength}`;
          }, side);
          check(/^200 video\/mp4 [1-9]/.test(served), `${side} video: ${served}`);
        } else {
          await page.waitForFunction((s) => { const i = document.querySelector(`#${s}-media img`); return i && i.complete && i.naturalWidth > 0; }, side);
        }
      }
      check(await page.isDisabled("#next"), "Next enabled before answering");
      const answers = { Q1: k % 2 === 0 ? "left" : "right", Q2: k % 3 === 0 ? "right" : "left" };
      await page.check(`input[name="Q1"][value="${answers.Q1}"]`);
      check(await page.isDisabled("#next"), "Next enabled with one answer missing");
      await page.check(`input[name="Q2"][value="${answers.Q2}"]`);
      await page.click("#next");
      await page.waitForFunction((prev) => document.querySelector("#study").dataset.trial !== prev || !document.querySelector("#done").hidden, String(index));
      choices.push({ index, answers });
    };
    const half = Math.floor(total / 2);
    for (let k = 0; k < half; k++) await answerOne(k);
    // Reload mid-way: the page resumes at the next unanswered comparison.
    await page.reload();
    await page.waitForSelector("#study:not([hidden])");
    const after = (await page.textContent("#progress")).trim();
    check(after === `${half + 1} / ${total}`, `after reload the page shows ${after}`);
    // A fresh visit without the id in the URL resumes through localStorage too.
    await page.goto(`${base}/`);
    await page.waitForSelector("#study:not([hidden])");
    check((await page.textContent("#progress")).trim() === `${half + 1} / ${total}`, "localStorage resume");
    for (let k = half; k < total; k++) await answerOne(k);
    await page.waitForSelector("#done:not([hidden])");
    check((await page.textContent("#progress")).trim() === `${total} / ${total}`, "final progress");
    await page.screenshot({ path: path.join(path.dirname(resultPath), "done.png") });
    return { participant, total, choices };
  } finally {
    await context.close();
    fs.rmSync(userDataDir, { recursive: true, force: true });
  }
}

// Malformed and out-of-order submissions are refused with a clear error.
async function protocolChecks() {
  let r = await json("POST", "/api/participants", { participant: "bad id!" });
  check(r.status === 400 && /participant id/.test(r.body.error), `bad id: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants", { participant: "proto" });
  check(r.status === 200 && r.body.answered === 0, `join: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants/proto/answers", undefined, "{not json");
  check(r.status === 400 && /malformed/.test(r.body.error), `bad JSON: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants/proto/answers", { index: 0, answers: { Q1: "left" } });
  check(r.status === 400 && /missing answer to Q2/.test(r.body.error), `missing: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants/proto/answers", { index: 0, answers: { Q1: "left", Q2: "middle" } });
  check(r.status === 400 && /"left" or "right"/.test(r.body.error), `bad side: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants/proto/answers", { index: 1, answers: { Q1: "left", Q2: "left" } });
  check(r.status === 409 && /not the next/.test(r.body.error), `out of order: ${JSON.stringify(r)}`);
  r = await json("POST", "/api/participants/nobody/answers", { index: 0, answers: { Q1: "left", Q2: "left" } });
  check(r.status === 404, `unknown participant: ${JSON.stringify(r)}`);
  r = await json("GET", "/api/participants/proto");
  check(r.status === 200 && r.body.answered === 0, "refused answers were not stored");
}

// Many participants at once through the API; each answer is also re-sent once (a retry).
async function simulatedParticipant(k) {
  const participant = `sim-${k}`;
  let state = (await json("POST", "/api/participants", { participant })).body;
  const choices = [];
  let step = 0;
  while (!state.done) {
    const index = state.trial.index;
    const answers = { Q1: (k + step) % 2 === 0 ? "left" : "right", Q2: (k * 7 + step) % 3 === 0 ? "left" : "right" };
    let r = await json("POST", `/api/participants/${participant}/answers`, { index, answers });
    check(r.status === 200, `${participant} answer ${index}: ${JSON.stringify(r)}`);
    const retry = await json("POST", `/api/participants/${participant}/answers`, { index, answers });
    check(retry.status === 200, `${participant} retry ${index}: ${JSON.stringify(retry)}`);
    choices.push({ index, answers });
    state = r.body;
    step++;
  }
  return { participant, total: state.total, choices };
}

(async () => {
  await protocolChecks();
  const sessions = [await browserSession()];
  const sims = await Promise.all(Array.from({ length: simulated }, (_, k) => simulatedParticipant(k)));
  fs.writeFileSync(resultPath, JSON.stringify({ sessions: sessions.concat(sims) }));
  console.log(`e2e ok: 1 browser session + ${simulated} simulated participants`);
})().catch((err) => {
  console.error(err.stack || String(err));
  process.exit(1);
});
