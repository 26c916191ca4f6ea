// Drives the servoamp live view (index.html: Foxglove Studio with the
// servoamp layout) in Debian's Chromium through playwright-core, as a user
// would, and reports what the page shows as JSON lines on stdout:
//
//   node drive.mjs --page URL --out DIR [--param NAME --good V --bad V]
//                  [--timeout S] [--min-cycles N] [--chromium PATH] [--name NAME]
//
//   {"event":"ready", ...}    Studio connected, every panel of the layout
//                             mounted, the topics advertised, the parameters
//                             listed: the caller may start the data now
//   {"event":"result", ...}   what every panel showed (plots: their data
//                             through each panel's "Download plot data as
//                             CSV"), the topics' counts and rates, Studio's
//                             problems, then the parameter set in the
//                             Parameters panel (--good, then --bad)
//   {"event":"stage", ...}    each stage as it begins (load, layout, connect,
//                             data, plots, problems, set good, set bad, done)
//   {"event":"error", ...}    and exit 1 (a screenshot studio-failure.png)
//
// Screenshots in DIR: studio-host.png (every panel with data, the topics
// with their rates), studio-param-refused.png (the refused value among
// Studio's problems). Requests to any host but 127.0.0.1 are refused
// (listed in the result as "blocked").
//
// Every timeout here counts the time Chromium could run (hoststall.mjs):
// time the host held its processes off its CPUs (other QEMUs, other load)
// is added, at most CAP times the timeout in all.

import fs from "node:fs";
import path from "node:path";
import { parseArgs } from "node:util";
import { chromium, errors } from "playwright-core";

import { runClock } from "./hoststall.mjs";

const { values: opt } = parseArgs({
  options: {
    page: { type: "string" },
    out: { type: "string" },
    param: { type: "string", default: "pos_kp" },
    good: { type: "string" },
    bad: { type: "string" },
    timeout: { type: "string", default: "120" },
    "min-cycles": { type: "string", default: "1000" },
    chromium: { type: "string", default: "/usr/bin/chromium" },
    name: { type: "string", default: "host" },
  },
});
if (!opt.page || !opt.out) {
  console.error("usage: node drive.mjs --page URL --out DIR [--param NAME --good V --bad V]");
  process.exit(2);
}
const TIMEOUT_MS = Number(opt.timeout) * 1000;
const MIN_CYCLES = Number(opt["min-cycles"]);
fs.mkdirSync(opt.out, { recursive: true });

const CHROMIUM_ARGS = [
  "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
];

const t0 = Date.now();
const emit = (obj) => process.stdout.write(JSON.stringify({ t_s: (Date.now() - t0) / 1000, ...obj }) + "\n");
const log = (msg) => process.stderr.write(`[drive ${((Date.now() - t0) / 1000).toFixed(1)}s] ${msg}\n`);

/**
 * Runs attempt(timeoutMs), a Playwright action, within budgetMs of the time
 * Chromium could run: a Playwright timeout in which the host held Chromium
 * off its CPUs is not the page's, and the action is tried again with what
 * is left (an action that timed out waiting for its element did nothing).
 */
async function patient(what, budgetMs, attempt) {
  const clock = runClock();
  for (;;) {
    try {
      return await attempt(Math.max(clock.left(budgetMs), 1000));
    } catch (e) {
      if (!(e instanceof errors.TimeoutError)) throw e;
      if (clock.spent(budgetMs)) {
        e.message = `${what}: ${e.message} (${clock.describe()})`;
        throw e;
      }
      log(`${what}: timed out with Chromium held off its CPUs (${clock.describe()}): trying again`);
    }
  }
}

const userDataDir = fs.mkdtempSync(path.join(opt.out, "chromium-profile-"));
const context = await patient("launching Chromium", 60_000, (timeout) => chromium.launchPersistentContext(userDataDir, {
  executablePath: opt.chromium,
  args: CHROMIUM_ARGS,
  viewport: { width: 1600, height: 1000 },
  acceptDownloads: true,
  timeout,
}));
const page = context.pages()[0] ?? (await context.newPage());
page.setDefaultTimeout(60_000);

const blocked = [];
const pageErrors = [];
const consoleErrors = [];
await context.route("**/*", (route) => {
  const u = new URL(route.request().url());
  if (u.protocol === "blob:" || u.protocol === "data:" || u.hostname === "127.0.0.1") {
    return route.continue();
  }
  blocked.push(u.href);
  return route.abort();
});
page.on("pageerror", (e) => pageErrors.push(String(e).slice(0, 500)));
// The protocol's requests the page sends (JSON text frames): a set is done
// when Studio sent it, not when its table shows the typed text.
const sentOps = [];
page.on("websocket", (ws) => {
  ws.on("framesent", (f) => {
    if (typeof f.payload !== "string") return;
    try {
      const j = JSON.parse(f.payload);
      sentOps.push({ op: j.op, parameters: j.parameters });
    } catch {
      /* not JSON: not a request */
    }
  });
});
page.on("console", (m) => {
  if (m.type() === "error") consoleErrors.push(m.text().slice(0, 500));
});

const median = (a) => {
  if (a.length === 0) return null;
  const b = [...a].sort((x, y) => x - y);
  return b[Math.floor(b.length / 2)];
};

/** Polls fn (run in the page) until it returns a truthy value, for
 * timeoutMs of the time Chromium could run. */
async function waitFor(what, fn, arg, timeoutMs = TIMEOUT_MS) {
  const clock = runClock();
  let last;
  for (;;) {
    try {
      last = await page.evaluate(fn, arg);
    } catch (e) {
      last = { evaluateError: String(e) };
    }
    if (last && !last.evaluateError && last.ok !== false) return last;
    if (clock.spent(timeoutMs)) throw new Error(`timed out waiting for ${what} (${clock.describe()}): ${JSON.stringify(last)}`);
    await page.waitForTimeout(500);
  }
}

// -- what the page shows (run in the page) -------------------------------------------
const panelSel = (id) => `[data-testid="panel-mouseenter-container ${id}"]`;

function readTopics() {
  const out = {};
  for (const el of document.querySelectorAll("[data-topic][data-topic-stat]")) {
    const t = el.dataset.topic;
    out[t] = out[t] ?? {};
    out[t][el.dataset.topicStat] = el.innerText.trim();
  }
  return out;
}

function readPanels(ids) {
  const out = {};
  for (const id of ids) {
    const el = document.querySelector(`[data-testid="panel-mouseenter-container ${id}"]`);
    out[id] = el ? { text: el.innerText } : null;
  }
  return out;
}

function readProblemsTab() {
  const tabs = [...document.querySelectorAll('[role="tab"]')];
  const tab = tabs.find((t) => t.innerText.trim().startsWith("Problems"));
  return { tab: tab ? tab.innerText.trim() : null, selected: tab?.getAttribute("aria-selected") === "true" };
}

// A parameter's row as it is on screen: ok once the row is there and its
// value box shows a value. Studio keys each row by its value, so a new value
// mounts a new row, whose box (@uiw/react-textarea-code-editor) is empty
// for one frame: it copies its text in a passive effect, after the commit.
// A read in that frame saw "" (CI, stop 30), which is no value at all.
function readParameters(name) {
  const panel = document.querySelector('[data-testid="panel-mouseenter-container Parameters!params"]');
  if (!panel) return { ok: false, why: "no Parameters panel" };
  const rows = [...panel.querySelectorAll("tr")].map((tr) => {
    const ta = tr.querySelector("textarea");
    return { text: tr.innerText.trim(), input: ta ? ta.value : null };
  });
  const row = rows.find((r) => r.text.split(/\s/)[0] === name);
  if (row === undefined) return { ok: false, why: `no row ${name}`, rows };
  if (row.input !== null && row.input.trim() === "") return { ok: false, why: `row ${name} not drawn yet`, rows, row };
  return { ok: true, rows, row };
}

// -- steps -----------------------------------------------------------------------------
const result = { blocked, pageErrors, consoleErrors };
let stage = "load";  // where a failure happened
const stageAt = {};
const setStage = (name) => {
  stage = name;
  stageAt[name] = (Date.now() - t0) / 1000;
  log(name);
  emit({ event: "stage", name });  // the caller may act on it (pause a board's stream)
};
try {
  log(`open ${opt.page}`);
  await patient("loading the page", 120_000, (timeout) => page.goto(opt.page, { waitUntil: "load", timeout }));
  const st = await waitFor("the page to render Studio", () => {
    const s = window.servoampViewer;
    if (s?.state === "failed") return { failed: s.error };
    return s?.state === "rendered" ? s : { ok: false, s };
  });
  if (st.failed) throw new Error(`viewer failed: ${st.failed}`);

  // the layout the page loaded: its panels, straight from the file it fetched
  setStage("layout");
  const layoutUrl = new URL("../foxglove/servoamp-layout.json", opt.page).href;
  const layout = await page.evaluate(async (u) => {
    const q = new URLSearchParams(window.location.search).get("layout");
    return (await fetch(q ? new URL(q, window.location.href) : u)).json();
  }, layoutUrl);
  const panelIds = Object.keys(layout.configById);
  result.panels_in_layout = panelIds;

  setStage("connect");
  const ready = await waitFor("Studio to connect: panels, topics, parameters", (a) => {
    const missing = a.ids.filter((id) => !document.querySelector(`[data-testid="panel-mouseenter-container ${id}"]`));
    const topics = [...document.querySelectorAll('[data-topic-stat="count"]')].map((e) => e.dataset.topic);
    const params = document.querySelector('[data-testid="panel-mouseenter-container Parameters!params"]');
    const hasParam = params ? [...params.querySelectorAll("tr")].some((tr) => tr.innerText.trim().split(/\s/)[0] === a.param) : false;
    const ok = missing.length === 0 && topics.length > 0 && hasParam;
    return { ok, missing, topics, hasParam };
  }, { ids: panelIds, param: opt.param });
  result.topics_advertised = ready.topics;
  emit({ event: "ready", topics: ready.topics, panels: panelIds });

  setStage("data");
  log("waiting for data in every panel");
  const plots = panelIds.filter((id) => id.startsWith("Plot!"));
  const texts = panelIds.filter((id) => !id.startsWith("Plot!") && !id.startsWith("Parameters!"));
  await waitFor(`${MIN_CYCLES} cycles and a message in every text panel`, (a) => {
    const counts = {};
    for (const el of document.querySelectorAll('[data-topic-stat="count"]')) {
      counts[el.dataset.topic] = Number(el.innerText.replace(/[^0-9]/g, "")) || 0;
    }
    const waiting = a.texts.filter((id) => {
      const el = document.querySelector(`[data-testid="panel-mouseenter-container ${id}"]`);
      return !el || /Waiting for next message|No messages/i.test(el.innerText) || el.innerText.trim().split("\n").length < 3;
    });
    return { ok: (counts["/servoamp/cycle"] ?? 0) >= a.min && waiting.length === 0, counts, waiting };
  }, { texts, min: MIN_CYCLES });
  // the rate is computed over a window: let it settle on the stream
  await page.waitForTimeout(3000);
  result.topics = await page.evaluate(readTopics);
  result.text_panels = await page.evaluate(readPanels, texts);

  setStage("plots");
  result.plots = {};
  for (const id of plots) {
    const panel = page.locator(panelSel(id));
    const button = panel.locator('button[title="Download plot data as CSV"], button:has([data-testid="DownloadIcon"])').first();
    const [download] = await patient(`${id}'s CSV`, 60_000, (timeout) =>
      Promise.all([page.waitForEvent("download", { timeout }), button.click({ timeout })]));
    const file = path.join(opt.out, `plot-${id.replace(/[^A-Za-z0-9]+/g, "_")}.csv`);
    await download.saveAs(file);
    const lines = fs.readFileSync(file, "utf8").split("\n").filter((l) => l.length > 0);
    const series = {};
    for (const line of lines.slice(1)) {
      // x, receive time, header.stamp, label, value (labels have no commas here)
      const f = line.split(",");
      const label = f.slice(3, f.length - 1).join(",");
      const v = Number(f[f.length - 1]);
      const x = Number(f[0]);
      const s = (series[label] = series[label] ?? { n: 0, finite: 0, min: Infinity, max: -Infinity, xmin: Infinity, xmax: -Infinity, values: [] });
      s.n++;
      if (Number.isFinite(v) && Number.isFinite(x)) {
        s.finite++;
        s.values.push(v);
        s.min = Math.min(s.min, v);
        s.max = Math.max(s.max, v);
        s.xmin = Math.min(s.xmin, x);
        s.xmax = Math.max(s.xmax, x);
      }
    }
    for (const s of Object.values(series)) s.median = median(s.values);
    for (const s of Object.values(series)) delete s.values;
    const text = await panel.innerText();
    result.plots[id] = { header: lines[0], series, text };
  }

  // Studio's problems as the sidebar shows them without a click: the
  // Problems tab carries their count (switching tabs would reset the rates)
  setStage("problems");
  result.problems_before = await page.evaluate(readProblemsTab);
  result.topics = await page.evaluate(readTopics);
  await patient("the screenshot", 60_000, (timeout) =>
    page.screenshot({ path: path.join(opt.out, `studio-${opt.name}.png`), timeout }));
  await patient("the Problems tab", 60_000, (timeout) => page.getByRole("tab", { name: /^Problems/ }).click({ timeout }));
  result.problems_before.list = await waitFor("the problems list", () => {
    const none = [...document.querySelectorAll("p, span, div")].some((e) => e.childElementCount === 0 && e.innerText?.trim() === "No problems found");
    const items = [...document.querySelectorAll(".MuiListItemText-primary")].map((e) => e.innerText.trim());
    return { ok: none || items.length > 0, none, items };
  });

  // -- the Parameters panel: type a value, submit, as a user does ----------------------
  // Studio lists the parameters again every 15 s, and the answer re-renders
  // the rows: an edit typed just before is lost (its Submit button goes, or
  // the click lands on the old row and nothing is sent), while the row still
  // shows the typed text. So a set counts once the page sent setParameters
  // with the value; until then, as a user would, type it again.
  const sentSet = (value, from) => sentOps.slice(from).some((o) => o.op === "setParameters" &&
    (o.parameters ?? []).some((q) => q.name === opt.param && Number(q.value) === Number(value)));
  const setParam = async (value) => {
    const params = page.locator(panelSel("Parameters!params"));
    const row = params.locator("tr", { hasText: opt.param }).first();
    for (let attempt = 1; ; attempt++) {
      const from = sentOps.length;
      const box = row.locator("textarea").first();
      await patient(`the ${opt.param} box`, 60_000, (timeout) => box.click({ timeout }));
      await patient(`typing into the ${opt.param} box`, 60_000, (timeout) => box.fill(String(value), { timeout }));
      try {
        await row.getByRole("button", { name: "Submit change" }).click({ timeout: 5_000 });
      } catch (e) {
        if (attempt >= 5) throw e;
      }
      for (let i = 0; i < 30 && !sentSet(value, from); i++) await page.waitForTimeout(100);
      if (sentSet(value, from)) return attempt;
      if (attempt >= 5) throw new Error(`no setParameters for ${opt.param} = ${value} after ${attempt} tries`);
      log(`the ${opt.param} row re-rendered before its Submit (try ${attempt}): typing it again`);
    }
  };
  if (opt.good !== undefined) {
    setStage("set good");
    const before = await waitFor(`the ${opt.param} row`, readParameters, opt.param);
    const tries = await setParam(opt.good);
    const after = await waitFor(`${opt.param} = ${opt.good} in the Parameters panel`, (a) => {
      const panel = document.querySelector('[data-testid="panel-mouseenter-container Parameters!params"]');
      const tr = [...(panel?.querySelectorAll("tr") ?? [])].find((r) => r.innerText.trim().split(/\s/)[0] === a.name);
      const v = tr?.querySelector("textarea")?.value ?? tr?.innerText;
      return { ok: v !== undefined && Number(v) === Number(a.value), value: v };
    }, { name: opt.param, value: opt.good });
    result.set_good = { before: before.row, shown: after.value, tries };
    // the controller's answer comes back through the bridge: wait for Studio's next poll
    // to list the value too (the parameters are listed again every 15 s)
  }
  if (opt.bad !== undefined) {
    setStage("set bad");
    await patient("the Problems tab", 60_000, (timeout) => page.getByRole("tab", { name: /^Problems/ }).click({ timeout }));
    await setParam(opt.bad);
    const refused = await waitFor("the refusal among Studio's problems", (a) => {
      const items = [...document.querySelectorAll(".MuiListItemText-primary")].map((e) => e.innerText.trim());
      const err = items.filter((t) => t.includes(a.name));
      return { ok: err.length > 0, items };
    }, { name: opt.param });
    // the value the controller kept: Studio shows the answer in the row, or
    // (when the refusal came within the same frame as the typed value) the
    // row keeps the typed text with its Submit/Reset buttons, and Reset
    // brings back the value Studio holds, as a user would do
    const row = page.locator(panelSel("Parameters!params")).locator("tr", { hasText: opt.param }).first();
    let kept;
    let reset = false;
    const clock = runClock();
    for (;;) {
      kept = await page.evaluate(readParameters, opt.param);
      if (kept.ok && Number(kept.row.input) !== Number(opt.bad)) break;
      if (clock.spent(TIMEOUT_MS)) throw new Error(`${opt.param} still shows ${opt.bad} (${clock.describe()}): ${JSON.stringify(kept)}`);
      const resetButton = row.getByRole("button", { name: "Reset" });
      if (kept.ok && await resetButton.count()) {
        await patient("the Reset button", 60_000, (timeout) => resetButton.click({ timeout }));
        reset = true;
      }
      await page.waitForTimeout(500);
    }
    const tab = await page.evaluate(readProblemsTab);
    result.set_bad = { problems: refused.items, shown_after: kept.row.input, reset, problems_tab: tab };
    const refusedShot = opt.name === "host" ? "studio-param-refused.png" : `studio-${opt.name}-param-refused.png`;
    await patient("the screenshot", 60_000, (timeout) => page.screenshot({ path: path.join(opt.out, refusedShot), timeout }));
  }
  result.params_final = await waitFor(`the ${opt.param} row`, readParameters, opt.param);
  setStage("done");
  fs.writeFileSync(path.join(opt.out, "result.json"), JSON.stringify({ stages: stageAt, ...result }, null, 1));
  emit({ event: "result", stages: stageAt, ...result });
} catch (e) {
  log(`failed at ${stage}: ${e.stack ?? e}`);
  try {
    await page.screenshot({ path: path.join(opt.out, "studio-failure.png"), timeout: 30_000 });
  } catch (e2) {
    log(`no failure screenshot: ${e2}`);
  }
  emit({ event: "error", stage, message: String(e.message ?? e), ...result });
  process.exitCode = 1;
} finally {
  await context.close();
  fs.rmSync(userDataDir, { recursive: true, force: true });
}
