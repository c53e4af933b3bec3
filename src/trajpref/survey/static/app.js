// The rating page of `trajpref survey serve`. Plain JavaScript, no libraries.
// Every answer is sent to the server as soon as both questions of a picture are rated, and
// the server is the only record: reloading the page, or entering the same rater id on
// another day, resumes from what it holds. A study with a consent text shows it after the rater
// id and before the first picture; the server takes answers only once the rater agreed.
// The browser remembers its last rater id (localStorage) and resumes that rater's session on
// the next visit; on a shared machine the next person may not be that rater, so a resumed
// session says whose it is, with a "Not you? Start as a new rater" control.
// The server gives each rater the order of the scenes and of the pictures within each scene
// (the same at every visit, another for another rater); the page numbers the pictures by where
// it shows them ("picture 2 of 4"), never by their letters.
"use strict";

const RATER_KEY = "trajpref-survey-rater";
const $ = (id) => document.getElementById(id);

const state = {
  study: null, // the public study from /api/study
  items: [], // every panel in this rater's order: {scene, panel, image, reference, sceneNo,
  // panelNo, panels} (panelNo of panels within the scene; from the server's progress.order)
  rater: null,
  resumed: false, // the rater came from this browser's memory, not typed in this visit
  pos: 0, // index into items
  answers: {}, // "scene/panel" -> {social, kinetics}: what the server holds
  draft: {}, // "scene/panel" -> {social?, kinetics?}: ratings not yet sent
  active: 0, // index of the highlighted criterion
  saving: Promise.resolve(), // answers are sent one after another, in order
};

const keyOf = (item) => `${item.scene}/${item.panel}`;

function show(view) {
  for (const id of ["login", "consent", "rate", "done", "failure"]) $(id).hidden = id !== view;
  $("progress-box").hidden = view !== "rate";
  // whose session this browser resumed, with the way out: shown until the rater is changed
  const note = state.resumed && !!state.rater && view !== "login" && view !== "failure";
  $("resume-note").hidden = !note;
  $("resume-rater").textContent = note ? state.rater : "";
  document.body.dataset.view = view;
}

function newRater() {
  // forget the remembered rater: the login form, empty, for the person at the keyboard
  localStorage.removeItem(RATER_KEY);
  state.rater = null;
  state.resumed = false;
  $("rater").value = "";
  show("login");
  $("rater").focus();
}

function fail(message) {
  $("failure-text").textContent = message;
  show("failure");
}

async function api(method, path, body) {
  const options = { method, headers: {} };
  if (body !== undefined) {
    options.headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  const response = await fetch(path, options);
  let data = null;
  try {
    data = await response.json();
  } catch (e) {
    data = null;
  }
  if (!response.ok) {
    const message = data && data.error ? data.error : `HTTP ${response.status}`;
    const error = new Error(message);
    error.status = response.status;
    throw error;
  }
  return data;
}

function answered() {
  return state.items.filter((item) => state.answers[keyOf(item)]).length;
}

function firstOpen() {
  const i = state.items.findIndex((item) => !state.answers[keyOf(item)]);
  return i < 0 ? state.items.length - 1 : i;
}

function ratingsOf(item) {
  return Object.assign({}, state.answers[keyOf(item)] || {}, state.draft[keyOf(item)] || {});
}

function buildCriteria() {
  const box = $("criteria");
  box.textContent = "";
  state.study.criteria.forEach((c, ci) => {
    const row = document.createElement("div");
    row.className = "criterion";
    row.dataset.criterion = c.id;
    const label = document.createElement("div");
    label.className = "label";
    const strong = document.createElement("strong");
    strong.textContent = c.label;
    const help = document.createElement("span");
    help.className = "help";
    help.textContent = c.help;
    label.append(strong, help);
    const buttons = document.createElement("div");
    buttons.className = "scale";
    const [lo, hi] = state.study.scale;
    for (let v = lo; v <= hi; v++) {
      const b = document.createElement("button");
      b.type = "button";
      b.className = "rate";
      b.dataset.criterion = c.id;
      b.dataset.value = String(v);
      b.textContent = String(v);
      b.setAttribute("aria-pressed", "false");
      b.addEventListener("click", () => {
        state.active = ci;
        rate(c.id, v);
      });
      buttons.append(b);
    }
    const ends = document.createElement("div");
    ends.className = "ends";
    ends.innerHTML = "<span>not plausible</span><span>fully plausible</span>";
    row.append(label, buttons, ends);
    box.append(row);
  });
}

function render() {
  const item = state.items[state.pos];
  const ratings = ratingsOf(item);
  const n = state.items.length;
  const done = answered();
  $("panel-image").src = item.image;
  $("reference-box").hidden = !item.reference;
  if (item.reference) $("reference-image").src = item.reference;
  $("where").textContent =
    `Scene ${item.sceneNo} of ${state.study.scenes.length} · picture ${item.panelNo} of ` +
    `${item.panels} (${state.pos + 1} of ${n})`;
  $("progress").max = n;
  $("progress").value = done;
  $("progress-text").textContent = `${done} / ${n} answered`;
  document.body.dataset.answered = String(done);
  document.body.dataset.pos = String(state.pos);
  document.querySelectorAll(".criterion").forEach((row, ci) => {
    row.classList.toggle("active", ci === state.active);
    row.querySelectorAll("button.rate").forEach((b) => {
      const on = ratings[b.dataset.criterion] === Number(b.dataset.value);
      b.classList.toggle("selected", on);
      b.setAttribute("aria-pressed", on ? "true" : "false");
    });
  });
  $("back").disabled = state.pos === 0;
  $("next").disabled = state.pos === n - 1 || !state.answers[keyOf(item)];
  $("submit").hidden = done < n;
  // fetch the next picture while this one is rated
  if (state.pos + 1 < n) new Image().src = state.items[state.pos + 1].image;
}

function setStatus(text, isError) {
  $("status").textContent = text;
  $("status").classList.toggle("error", !!isError);
}

function moveTo(pos) {
  state.pos = Math.max(0, Math.min(state.items.length - 1, pos));
  const ratings = ratingsOf(state.items[state.pos]);
  const open = state.study.criteria.findIndex((c) => ratings[c.id] === undefined);
  state.active = open < 0 ? 0 : open;
  render();
}

function rate(criterion, value) {
  const item = state.items[state.pos];
  const key = keyOf(item);
  state.draft[key] = Object.assign(state.draft[key] || {}, { [criterion]: value });
  const ratings = ratingsOf(item);
  const criteria = state.study.criteria;
  const ci = criteria.findIndex((c) => c.id === criterion);
  const complete = criteria.every((c) => ratings[c.id] !== undefined);
  const lastQuestion = ci === criteria.length - 1;
  state.active = (ci + 1) % criteria.length;
  render();
  if (!complete) return;
  const body = {};
  for (const c of criteria) body[c.id] = ratings[c.id];
  const advance = lastQuestion && state.pos < state.items.length - 1;
  if (advance) moveTo(state.pos + 1);
  save(item, body);
}

function save(item, body) {
  const key = keyOf(item);
  setStatus("saving…");
  state.saving = state.saving.then(async () => {
    try {
      const path =
        `api/raters/${encodeURIComponent(state.rater)}/answers/` +
        `${encodeURIComponent(item.scene)}/${encodeURIComponent(item.panel)}`;
      await api("PUT", path, body);
      state.answers[key] = body;
      const draft = state.draft[key] || {};
      if (Object.keys(draft).every((c) => draft[c] === body[c])) delete state.draft[key];
      setStatus("saved");
    } catch (e) {
      setStatus(`not saved: ${e.message}`, true);
      state.pos = state.items.indexOf(item);
      if (e.status === 403 && state.study.consent) {
        showConsent(); // not (or no longer) agreed to the consent text
        return;
      }
    }
    render();
  });
  return state.saving;
}

async function startRater(rater, resumed = false) {
  state.rater = rater;
  state.resumed = resumed;
  state.answers = {};
  state.draft = {};
  let progress;
  try {
    progress = await api("GET", `api/raters/${encodeURIComponent(rater)}`);
  } catch (e) {
    localStorage.removeItem(RATER_KEY);
    state.resumed = false;
    show("login");
    $("rater").value = rater;
    setLoginError(e.message);
    return;
  }
  localStorage.setItem(RATER_KEY, rater);
  if (progress.submitted) {
    show("done");
    return;
  }
  if (progress.consent_required && !progress.consented) {
    showConsent();
    return;
  }
  beginRating(progress);
}

function showConsent() {
  $("consent-error").textContent = "";
  show("consent");
  $("agree").focus();
}

async function agree() {
  // JSON naming the text shown (its hash): the server records which text the rater agreed to
  // and refuses a hash of another text (409), e.g. one edited since this page was loaded.
  const body = { agree: true, text_hash: state.study.consent_hash };
  try {
    await api("POST", `api/raters/${encodeURIComponent(state.rater)}/consent`, body);
  } catch (e) {
    $("consent-error").textContent = `not recorded: ${e.message}`;
    if (e.status === 409) await reloadConsent();
    return;
  }
  startRater(state.rater, state.resumed); // the server's record again: resumes where the rater is
}

async function reloadConsent() {
  // The server holds another consent text than the one shown: show that one to be read.
  try {
    const study = await api("GET", "api/study");
    state.study.consent = study.consent;
    state.study.consent_hash = study.consent_hash;
    $("consent-text").textContent = study.consent || "";
    $("consent-error").textContent = "The consent text has changed: please read it again.";
  } catch (e) {
    // keep the message of the refused agreement
  }
}

function setOrder(order) {
  // this rater's order of the scenes and of the pictures within each scene (the server's)
  const scenes = {};
  for (const scene of state.study.scenes) scenes[scene.id] = scene;
  const images = {};
  for (const scene of state.study.scenes) {
    for (const panel of scene.panels) images[`${scene.id}/${panel.id}`] = panel.image;
  }
  state.items = [];
  order.forEach((entry, si) => {
    entry.panels.forEach((panel, pi) => {
      state.items.push({
        scene: entry.scene, panel, image: images[`${entry.scene}/${panel}`],
        reference: scenes[entry.scene].reference, sceneNo: si + 1, panelNo: pi + 1,
        panels: entry.panels.length,
      });
    });
  });
}

function beginRating(progress) {
  setOrder(progress.order);
  state.answers = {};
  for (const [scene, panels] of Object.entries(progress.answers)) {
    for (const [panel, ratings] of Object.entries(panels)) {
      state.answers[`${scene}/${panel}`] = ratings;
    }
  }
  show("rate");
  moveTo(firstOpen());
  setStatus(answered() ? `welcome back, ${state.rater}` : `hello, ${state.rater}`);
}

function setLoginError(text) {
  let p = $("login-error");
  if (!p) {
    p = document.createElement("p");
    p.id = "login-error";
    p.className = "error";
    $("login-form").after(p);
  }
  p.textContent = text;
}

async function submitAll() {
  await state.saving;
  try {
    await api("POST", `api/raters/${encodeURIComponent(state.rater)}/submit`, { submit: true });
  } catch (e) {
    setStatus(`not submitted: ${e.message}`, true);
    return;
  }
  localStorage.removeItem(RATER_KEY);
  show("done");
}

function onKey(event) {
  if (document.body.dataset.view !== "rate") return;
  if (event.altKey || event.ctrlKey || event.metaKey) return;
  const [lo, hi] = state.study.scale;
  const v = Number(event.key);
  if (Number.isInteger(v) && v >= lo && v <= hi) {
    event.preventDefault();
    rate(state.study.criteria[state.active].id, v);
  } else if (event.key === "ArrowLeft") {
    event.preventDefault();
    if (state.pos > 0) moveTo(state.pos - 1);
  } else if (event.key === "ArrowRight") {
    event.preventDefault();
    if (!$("next").disabled) moveTo(state.pos + 1);
  } else if (event.key === "ArrowUp" || event.key === "ArrowDown") {
    event.preventDefault();
    const n = state.study.criteria.length;
    state.active = (state.active + (event.key === "ArrowUp" ? n - 1 : 1)) % n;
    render();
  } else if (event.key === "Enter" && !$("submit").hidden) {
    event.preventDefault();
    submitAll();
  }
}

async function main() {
  try {
    state.study = await api("GET", "api/study");
  } catch (e) {
    fail(`The study could not be loaded: ${e.message}`);
    return;
  }
  document.title = state.study.title;
  $("title").textContent = state.study.title;
  $("instructions").textContent = state.study.instructions;
  $("consent-text").textContent = state.study.consent || "";
  buildCriteria();
  $("login-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const rater = $("rater").value.trim();
    if (!$("rater").checkValidity() || !rater) {
      setLoginError("Use 1-64 ASCII letters (A-Z, a-z), digits or _ . @ - (starting with a letter or digit).");
      return;
    }
    startRater(rater);
  });
  $("back").addEventListener("click", () => moveTo(state.pos - 1));
  $("next").addEventListener("click", () => moveTo(state.pos + 1));
  $("submit").addEventListener("click", submitAll);
  $("agree").addEventListener("click", agree);
  $("consent-back").addEventListener("click", newRater);
  $("switch-rater").addEventListener("click", newRater);
  $("not-me").addEventListener("click", newRater);
  document.addEventListener("keydown", onKey);
  const saved = localStorage.getItem(RATER_KEY);
  if (saved) {
    startRater(saved, true); // remembered by this browser: the page says whose session it is
  } else {
    show("login");
    $("rater").focus();
  }
}

main();
