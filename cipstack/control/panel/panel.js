// The front panel of cipstack's emulated devices: one device's panel, or the plant of a fleet.
// It calls the HTTP API's JSON operations like any client (same origin, same token) and reads the
// device live from its Server-Sent Events stream (/devices/ADDRESS/stream). Everything a device
// sends is shown as text (textContent), never as markup.
"use strict";

const $ = (id) => document.getElementById(id);
const TOKEN_KEY = "cipstack-token";
const TREND_SECONDS = 60;

// -- the API ----------------------------------------------------------------------------------------
class ApiError extends Error {
  constructor(status, message) { super(message); this.status = status; }
}

function headers(json) {
  const given = {};
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (token) given.Authorization = `Bearer ${token}`;
  if (json) given["Content-Type"] = "application/json";
  return given;
}

function askToken() {
  return new Promise((resolve) => {
    const dialog = $("token-dialog");
    $("token-form").onsubmit = () => {
      sessionStorage.setItem(TOKEN_KEY, $("token-input").value);
      resolve();
    };
    dialog.showModal();
    $("token-input").focus();
  });
}

async function api(method, path, body) {
  for (let attempt = 0; attempt < 3; attempt++) {
    const reply = await fetch(path, {method, headers: headers(body !== undefined),
                                     body: body === undefined ? undefined : JSON.stringify(body)});
    if (reply.status === 401) { await askToken(); continue; }
    const text = await reply.text();
    let value = null;
    try { value = text ? JSON.parse(text) : null; } catch (error) { value = {error: text}; }
    if (!reply.ok) throw new ApiError(reply.status, (value && value.error) || `HTTP ${reply.status}`);
    return value;
  }
  throw new ApiError(401, "the token was refused");
}

function element(tag, text, attributes) {
  const made = document.createElement(tag);
  if (text !== undefined && text !== null) made.textContent = String(text);
  for (const [name, value] of Object.entries(attributes || {})) made.setAttribute(name, value);
  return made;
}

function row(cells) {
  const tr = document.createElement("tr");
  for (const cell of cells) {
    const td = document.createElement("td");
    if (cell instanceof Node) td.appendChild(cell); else td.textContent = cell === null ? "-" : String(cell);
    tr.appendChild(td);
  }
  return tr;
}

function say(where, text, ok) {
  const target = $(where);
  target.textContent = text;
  target.className = "message " + (ok ? "ok" : "error");
}

// -- the live stream ----------------------------------------------------------------------------------
// fetch rather than EventSource: a token goes in a header, which EventSource cannot send.
async function follow(path, handlers, since) {
  for (;;) {
    try {
      const reply = await fetch(`${path}?since=${since()}`, {headers: headers(false)});
      if (reply.status === 401) { await askToken(); continue; }
      if (!reply.ok || !reply.body) throw new Error(`HTTP ${reply.status}`);
      setLink(true);
      const reader = reply.body.getReader();
      const decoder = new TextDecoder();
      let pending = "";
      for (;;) {
        const {value, done} = await reader.read();
        if (done) break;
        pending += decoder.decode(value, {stream: true});
        let end;
        while ((end = pending.indexOf("\n\n")) >= 0) {
          const block = pending.slice(0, end);
          pending = pending.slice(end + 2);
          let name = "message"; const data = [];
          for (const line of block.split("\n")) {
            if (line.startsWith("event: ")) name = line.slice(7);
            else if (line.startsWith("data: ")) data.push(line.slice(6));
          }
          if (data.length && handlers[name]) handlers[name](JSON.parse(data.join("\n")));
        }
      }
    } catch (error) {
      // the device's API went away (a stop, a worker that ended): say so and try again
    }
    setLink(false);
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

function setLink(up) {
  const state = $("link-state");
  state.textContent = up ? "live" : "not connected to the emulator; retrying";
  state.className = up ? "" : "down";
}

// -- one device's panel ---------------------------------------------------------------------------------
const panel = {prefix: "", connections: [], faultTable: [], events: [], samples: [], status: null};

async function openPanel(address) {
  panel.prefix = `/devices/${encodeURIComponent(address)}`;
  $("panel").hidden = false;
  $("title").textContent = address;
  document.title = `${address}: cipstack front panel`;
  wireControls();
  const [trips, table] = await Promise.all([api("GET", panel.prefix + "/trips"),
                                            api("GET", panel.prefix + "/fault-table")]);
  const select = $("trip-code");
  for (const trip of trips) select.appendChild(element("option", `${trip.label} (0x${trip.fault_code.toString(16).toUpperCase().padStart(4, "0")})`, {value: trip.code}));
  if (!trips.length) $("trip-form").hidden = true;
  panel.faultTable = table;
  for (const kind of table) $("fault-name").appendChild(element("option", kind.name, {value: kind.name}));
  showFaultForm();
  await loadParameters();
  setInterval(sample, 500);
  follow(panel.prefix + "/stream", {status: showStatus, faults: showFaults, connections: showConnections,
                                     events: addEvents},
         () => (panel.events.length ? panel.events[panel.events.length - 1].number : 0));
}

function wireControls() {
  const post = (path, body, message) => async () => {
    try { const result = await api("POST", panel.prefix + path, body); say("drive-message", message(result), true); }
    catch (error) { say("drive-message", error.message, false); }
  };
  $("trip-form").addEventListener("submit", (event) => {
    event.preventDefault();
    post("/trip", {code: $("trip-code").value}, (r) => r.result)();
  });
  $("reset").addEventListener("click", post("/reset", undefined, (r) => r.result));
  $("power-off").addEventListener("click", post("/power", {action: "cycle", off: "3600s"},
                                                 () => "power off (for up to an hour; Power on ends it)"));
  $("power-on").addEventListener("click", async () => {
    try { await api("DELETE", panel.prefix + "/faults/power-cycle"); say("drive-message", "power on", true); }
    catch (error) { say("drive-message", error.message, false); }
  });
  $("unplug").addEventListener("click", post("/link", {state: "unplug"}, () => "cable unplugged"));
  $("plug").addEventListener("click", post("/link", {state: "plug"}, () => "cable plugged"));
  $("fault-name").addEventListener("change", showFaultForm);
  $("fault-form").addEventListener("submit", applyFault);
  $("clear-all").addEventListener("click", () => clearFaults(""));
  $("parameter-filter").addEventListener("input", filterParameters);
  $("parameters-refresh").addEventListener("click", loadParameters);
  $("event-filter").addEventListener("input", showEvents);
}

function showStatus(status) {
  panel.status = status;
  const drive = status.drive || {};
  const tripped = Boolean(drive.trip);
  // The Control Supervisor's states (CIP): Enabled and Stopping are the motor energized.
  const running = /^(enabled|stopping)$/i.test(drive.state || "") && !tripped;
  const hz = drive.output_frequency_hz;
  if (!panel.shownParameter) {
    $("display").textContent = status.power === "off" ? "" : tripped ? String(drive.trip) :
      hz === undefined ? "-----" : Number(hz).toFixed(2);
  }
  $("display").className = tripped ? "tripped" : "";
  const lit = {"ind-run": running, "ind-stop": !running && status.power !== "off", "ind-fwd": drive.direction === "fwd",
               "ind-rev": drive.direction === "rev", "ind-trip": tripped};
  for (const [id, on] of Object.entries(lit)) $(id).classList.toggle("lit", on);
  $("state").textContent = stateText(drive.state);
  $("state").className = tripped ? "state-fault" : running ? "state-running" : "";
  $("output").textContent = hz === undefined ? "-" : `${Number(hz).toFixed(2)} Hz`;
  $("reference").textContent = referenceText(drive);
  $("direction").textContent = drive.direction || "-";
  $("current").textContent = (drive.not_simulated || []).includes("output_current_a") ? "not simulated" :
    drive.output_current_a === undefined ? "-" : `${Number(drive.output_current_a).toFixed(1)} A`;
  $("trip").textContent = drive.trip || "none";
  $("power").textContent = status.power;
  $("link").textContent = status.link;
  $("power").className = status.power === "off" ? "down" : "";
  const scenario = status.scenario;
  $("scenario").hidden = !scenario;
  if (scenario) {
    $("scenario").textContent = `Scenario ${scenario.file}: ${scenario.state}, ${scenario.fired} of ${scenario.steps} ` +
      `step(s) fired` + (scenario.next ? `; next: ${scenario.next}` : "");
  }
  $("link").className = status.link === "unplugged" ? "down" : "";
}

// The Control Supervisor's state (CIP), in one case whichever family names it: the ACG says READY,
// the MX2/RX ready.
function stateText(state) {
  return state ? String(state).toUpperCase() : "-";
}

// A word counted in steps of its unit ("0.01 Hz", "0.1 Hz", "RPM"), as the value it stands for:
// 3000 in 0.01 Hz is "30.00 Hz".
function scaledText(raw, unit) {
  const match = /^(\d+(?:\.(\d+))?) (.+)$/.exec(unit || "");
  if (!match) return `${raw} ${unit || ""}`.trim();
  return `${(Number(raw) * Number(match[1])).toFixed((match[2] || "").length)} ${match[3]}`;
}

// The speed reference in Hz: the ACG gives it so; the MX2/RX give the network's reference word in its
// unit (P049, d060: 0.01 Hz, 0.1 Hz or RPM), in Hz unless it counts RPM.
function referenceHz(drive) {
  if (drive.reference_hz !== undefined) return Number(drive.reference_hz);
  const match = /^(\d+(?:\.\d+)?) Hz$/.exec(drive.speed_unit || "");
  return match && drive.speed_reference !== undefined ? Number(drive.speed_reference) * Number(match[1]) : undefined;
}

function referenceText(drive) {
  const hz = referenceHz(drive);
  if (hz !== undefined) return `${hz.toFixed(2)} Hz`;
  return drive.speed_reference !== undefined ? scaledText(drive.speed_reference, drive.speed_unit) : "-";
}

// -- the trend: output and reference frequency of the last minute ----------------------------------------
// The frequency axis in round steps (1, 2, 2.5 or 5 times a power of ten; 0/20/40/60 Hz, not
// 0/13.8/27.5/41.3/55.0): the lowest top, 2 to 6 steps (4 where two tops are equal), at or above the
// highest value with a margin.
function trendTicks(highest) {
  const wanted = Math.max(10, Number(highest) || 0) * 1.05;
  let best = null;
  for (let power = Math.floor(Math.log10(wanted / 6)); power <= Math.ceil(Math.log10(wanted / 2)); power++) {
    for (const mantissa of [1, 2, 2.5, 5]) {
      const step = mantissa * 10 ** power;
      const count = Math.ceil(wanted / step - 1e-9);
      if (count < 2 || count > 6) continue;
      const top = step * count;
      if (!best || top < best.top - 1e-9 ||
          (Math.abs(top - best.top) <= 1e-9 && Math.abs(count - 4) < Math.abs(best.count - 4))) {
        best = {step, count, top};
      }
    }
  }
  return Array.from({length: best.count + 1}, (_, i) => Number((best.step * i).toFixed(6)));
}

function sample() {
  const drive = (panel.status && panel.status.drive) || {};
  const now = Date.now() / 1000;
  panel.samples.push([now, Number(drive.output_frequency_hz || 0), referenceHz(drive) || 0]);
  while (panel.samples.length && panel.samples[0][0] < now - TREND_SECONDS) panel.samples.shift();
  drawTrend(now);
}

function drawTrend(now) {
  const canvas = $("trend");
  const context = canvas.getContext("2d");
  const {width, height} = canvas;
  context.clearRect(0, 0, width, height);
  const ticks = trendTicks(Math.max(0, ...panel.samples.map((s) => Math.max(s[1], s[2]))));
  const top = ticks[ticks.length - 1];
  context.strokeStyle = "#d5dae0"; context.fillStyle = "#5b6470"; context.font = "11px sans-serif";
  for (const tick of ticks) {
    const y = height - 16 - (height - 34) * tick / top;
    context.beginPath(); context.moveTo(40, y); context.lineTo(width, y); context.stroke();
    context.fillText(String(tick), 2, y + 4);
  }
  canvas.setAttribute("aria-label", `output and reference frequency over the last minute, axis ${ticks.join(", ")} Hz`);
  context.fillText("Hz", 2, 10); context.fillText("-60 s", 40, height - 2); context.fillText("now", width - 24, height - 2);
  const x = (t) => 40 + (width - 40) * (1 - (now - t) / TREND_SECONDS);
  const y = (v) => height - 16 - (height - 34) * v / top;
  for (const [index, colour] of [[2, "#b35900"], [1, "#0969da"]]) {
    context.strokeStyle = colour; context.lineWidth = 2; context.beginPath();
    panel.samples.forEach((s, n) => (n ? context.lineTo(x(s[0]), y(s[index])) : context.moveTo(x(s[0]), y(s[index]))));
    context.stroke();
  }
}

// -- connections ----------------------------------------------------------------------------------------------
function dataCell(data) {
  const cell = document.createElement("div");
  if (!data) { cell.textContent = "-"; return cell; }
  const names = Object.entries(data.fields || {});
  if (names.length) {
    const list = element("ul", null, {class: "fields"});
    for (const [name, value] of names) list.appendChild(element("li", `${name} = ${value === true ? 1 : value === false ? 0 : value}`));
    cell.appendChild(list);
  }
  cell.appendChild(element("div", data.hex || "(no data)", {class: "hex"}));
  return cell;
}

function showConnections(all) {
  panel.connections = all.class1;
  $("sessions").textContent = `${all.sessions.length} session(s)` +
    (all.sessions.length ? `: ${all.sessions.map((s) => s.peer).join(", ")}` : "");
  const body = $("class1-table").tBodies[0];
  body.replaceChildren(...all.class1.map((c) => row([
    `${c.kind} ${c.ot_id} / ${c.to_id}`, c.originator, `${c.output === null ? "heartbeat" : c.output} → ${c.input}`,
    `${c.ot_rpi_us / 1000} ms / ${c.to_rpi_us / 1000} ms`, `${c.received} / ${c.lost}`, `${c.sent} / ${c.late}`,
    c.run === null ? "-" : c.run ? "run" : "idle", dataCell(c.output_data), dataCell(c.input_data)])));
  if (!all.class1.length) body.appendChild(row(["no class 1 connection", "", "", "", "", "", "", "", ""]));
  $("class3-table").tBodies[0].replaceChildren(...all.class3.map((c) => row([
    c.id, c.originator, c.requests, `${c.timeout_s} s`])));
  refreshConnectionChoices();
}

// -- faults ---------------------------------------------------------------------------------------------------
function showFaultForm() {
  const kind = panel.faultTable.find((k) => k.name === $("fault-name").value);
  const box = $("fault-options");
  box.replaceChildren();
  if (!kind) return;
  $("fault-summary").textContent = `${kind.summary} (acts on: ${kind.where})`;
  for (const option of kind.options) {
    const id = `fault-option-${option.name}`;
    const need = option.required ? " (required)" : option.one_of ? ` (${option.one_of.join(" or ")})` : "";
    box.appendChild(element("label", option.name + need, {for: id}));
    let input;
    if (option.name === "connection") {
      input = element("select", null, {id, "data-option": option.name});
    } else {
      input = element("input", null, {id, "data-option": option.name, placeholder: option.metavar,
                                      "aria-describedby": id + "-help"});
    }
    box.appendChild(input);
    box.appendChild(element("small", option.help, {id: id + "-help"}));
  }
  refreshConnectionChoices();
}

function refreshConnectionChoices() {
  const select = document.querySelector('#fault-options select[data-option="connection"]');
  if (!select) return;
  const chosen = select.value;
  select.replaceChildren(element("option", "every connection", {value: ""}),
    ...panel.connections.map((c) => element("option", `${c.ot_id} (${c.output === null ? "heartbeat" : c.output} → ${c.input}, ${c.originator})`, {value: c.ot_id})));
  select.value = [...select.options].some((o) => o.value === chosen) ? chosen : "";
}

async function applyFault(event) {
  event.preventDefault();
  const options = {};
  for (const input of document.querySelectorAll("#fault-options [data-option]")) {
    if (input.value.trim() !== "") options[input.dataset.option] = input.value.trim();
  }
  try {
    const fault = await api("POST", panel.prefix + "/faults", {name: $("fault-name").value, options});
    say("fault-message", `fault ${fault.id} applied: ${fault.name}`, true);
  } catch (error) { say("fault-message", error.message, false); }
}

async function clearFaults(which) {
  try {
    const cleared = await api("DELETE", panel.prefix + "/faults" + (which === "" ? "" : `/${which}`));
    say("fault-message", cleared.length ? `cleared ${cleared.map((f) => f.name).join(", ")}` : "no fault was active", true);
  } catch (error) { say("fault-message", error.message, false); }
}

function showFaults(faults) {
  $("faults-table").tBodies[0].replaceChildren(...faults.map((f) => {
    const button = element("button", "Clear", {type: "button", "aria-label": `clear fault ${f.id} ${f.name}`});
    button.addEventListener("click", () => clearFaults(String(f.id)));
    return row([f.id, f.name, JSON.stringify(f.options), f.remaining_s === undefined ? "until cleared" : `${f.remaining_s} s`, button]);
  }));
}

// -- parameters ---------------------------------------------------------------------------------------------
async function loadParameters() {
  let found;
  try { found = await api("GET", panel.prefix + "/parameters"); }
  catch (error) { $("parameters-note").textContent = error.message; return; }
  $("parameters-note").textContent =
    `${found.keypad}: a value is written with the keypad's rules, as over communication (not saved).`;
  const groups = $("parameter-groups");
  if (groups.childElementCount) {
    // Shown already: the values alone change, in place (a field being edited, and what the device
    // said beside a field, stay).
    for (const group of found.groups) for (const p of group.parameters) {
      const field = $(parameterId(p.code));
      if (field && document.activeElement !== field) field.value = p.value;
    }
    return;
  }
  const open = new Set([...groups.querySelectorAll("details[open]")].map((d) => d.dataset.group));
  groups.replaceChildren(...found.groups.map((group, index) => {
    const details = element("details", null, {"data-group": group.group});
    if (open.has(group.group) || (!open.size && index === 0)) details.open = true;
    details.appendChild(element("summary", `${group.group} (${group.parameters.length})`));
    const table = element("table");
    table.appendChild(element("thead")).appendChild(row(["Code", "Name", "Value", "Unit", "Range", ""]));
    const body = table.appendChild(element("tbody"));
    for (const p of group.parameters) body.appendChild(parameterRow(p));
    details.appendChild(table);
    return details;
  }));
  filterParameters();
}

function parameterId(code) {
  return `parameter-${code.replace(/[^A-Za-z0-9]/g, "_")}`;
}

function parameterRow(p) {
  const id = parameterId(p.code);
  const tr = element("tr", null, {class: "parameter", "data-search": `${p.code} ${p.name}`.toLowerCase()});
  const value = element("input", null, {id, value: p.value, "aria-label": `${p.code} ${p.name}`});
  if (!p.writable) value.readOnly = true;
  const note = element("span", p.meaning || (p.simulated === false ? "not simulated" : ""),
                       {class: "refusal-or-meaning", role: "status"});
  const form = element("form");
  form.append(value, " ", note);
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    try {
      const written = await api("PUT", `${panel.prefix}/parameters/${encodeURIComponent(p.code)}`, {value: value.value});
      value.value = written.value;
      note.textContent = written.meaning || "written";
      note.className = "refusal-or-meaning";
    } catch (error) {
      note.textContent = error.message;
      note.className = "refusal-or-meaning refusal";
    }
  });
  value.addEventListener("focus", () => { panel.shownParameter = p.code; $("display").textContent = `${p.code} ${value.value}`; });
  value.addEventListener("blur", () => { panel.shownParameter = null; if (panel.status) showStatus(panel.status); });
  const set = element("button", "Set", {type: "button", "aria-label": `set ${p.code}`});
  set.disabled = !p.writable;
  set.addEventListener("click", () => form.requestSubmit());
  const range = p.choices ? p.choices : `${p.minimum}..${p.maximum}`;
  for (const cell of [element("code", p.code), p.name, form, p.unit, element("span", range + (p.access.includes("stopped") ? " (stopped only)" : ""), {class: "range"}), set]) {
    const td = element("td");
    if (cell instanceof Node) td.appendChild(cell); else td.textContent = cell;
    tr.appendChild(td);
  }
  return tr;
}

function filterParameters() {
  const wanted = $("parameter-filter").value.trim().toLowerCase();
  for (const tr of document.querySelectorAll("#parameter-groups tr.parameter")) {
    tr.hidden = wanted !== "" && !tr.dataset.search.includes(wanted);
  }
  if (wanted) for (const details of document.querySelectorAll("#parameter-groups details")) {
    details.open = [...details.querySelectorAll("tr.parameter")].some((tr) => !tr.hidden);
  }
}

// -- events ---------------------------------------------------------------------------------------------------
function addEvents(events) {
  panel.events.push(...events);
  if (panel.events.length > 1000) panel.events.splice(0, panel.events.length - 1000);
  if (events.some((e) => e.kind === "parameter write")) loadParameters();
  showEvents();
}

function eventText(e) {
  const rest = Object.entries(e).filter(([k]) => !["number", "kind", "time", "monotonic"].includes(k))
    .map(([k, v]) => `${k}=${typeof v === "object" ? JSON.stringify(v) : v}`).join(" ");
  return `${e.time} #${e.number} ${e.kind} ${rest}`;
}

function showEvents() {
  const wanted = $("event-filter").value.trim().toLowerCase();
  const shown = panel.events.map(eventText).filter((t) => !wanted || t.toLowerCase().includes(wanted)).reverse();
  $("event-list").replaceChildren(...shown.slice(0, 300).map((t) => element("li", t)));
}

// -- the plant ------------------------------------------------------------------------------------------------
// One GET /plant a second brings every device's row (a thousand devices in one answer); the rows are kept,
// their cells changed where the value did, then sorted and filtered again. A summary counts the devices
// by state; a click on a count filters by it, a click on a column heading sorts by it (again: reversed).
const plant = {rows: new Map(), keys: new Map(), sortColumn: 0, descending: false, summary: new Map(), order: "",
  summaryTotal: null};
const PLANT_REFRESH_MS = 1000;
const OVERLOAD_SHARE = 0.01;

function addressNumber(address) {
  const parts = String(address).split(":")[0].split(".").map(Number);
  return parts.length === 4 && parts.every((p) => p >= 0 && p < 256)
    ? ((parts[0] * 256 + parts[1]) * 256 + parts[2]) * 256 + parts[3] : Number.MAX_SAFE_INTEGER;
}

function plantState(device) {
  if (device.error) return /ended/.test(device.error) ? "worker ended" : "not answering";
  if (device.state === undefined) return "…";
  const state = stateText(device.state);
  return device.trip ? `${state} (${device.trip})` : state;
}

function plantRow(device) {
  let tr = plant.rows.get(device.address);
  if (!tr) {
    const link = element("a", device.address, {href: `/?device=${encodeURIComponent(device.address)}`});
    tr = row([link, "-", "-", "…", "-", "-", "-", "-", "-"]);
    plant.rows.set(device.address, tr);
    $("plant-table").tBodies[0].appendChild(tr);
  }
  const state = plantState(device);
  if (device.error && device.error.includes("did not answer") && tr.dataset.state !== "…") {
    // A worker too busy to answer this refresh (its loop behind, overloaded): its devices keep what
    // they last said, the state says why it is not new.
    tr.cells[3].textContent = state;
    tr.cells[3].className = "down";
    tr.cells[3].title = device.error;
    tr.dataset.state = state;
    tr.dataset.search = `${device.address} ${tr.cells[1].textContent} ${tr.cells[2].textContent} ${state}`.toLowerCase();
    return;
  }
  const late = device.late === undefined ? "-" : `${device.late} / ${device.missed}`;
  const texts = [device.address, device.product_name || "-", device.worker === undefined ? "-" : String(device.worker),
    state, device.output_frequency_hz === undefined || device.output_frequency_hz === null ? "-"
      : `${Number(device.output_frequency_hz).toFixed(2)} Hz`,
    device.power === undefined ? "-" : `${device.power} / ${device.link}`,
    device.sessions === undefined ? "-"
      : `${device.sessions} sessions, ${device.class3_connections} class 3, ${device.class1_connections} class 1`,
    device.faults === undefined ? "-" : String(device.faults), late];
  for (let i = 1; i < texts.length; i++) if (tr.cells[i].textContent !== texts[i]) tr.cells[i].textContent = texts[i];
  const down = Boolean(device.error) || Boolean(device.trip);
  tr.cells[3].className = down ? "down" : "";
  tr.cells[3].title = device.error || "";
  // Overloaded, as a fleet judges its workers: more than 1 % of the production slots skipped (a
  // production past its half-millisecond tolerance alone is a busy machine).
  const overloaded = (device.missed || 0) > OVERLOAD_SHARE * ((device.sent || 0) + (device.missed || 0));
  tr.cells[8].className = overloaded ? "late" : "";
  tr.dataset.state = device.error || device.state === undefined ? state : stateText(device.state);
  tr.dataset.late = overloaded ? "late" : "";
  tr.dataset.search = `${texts.slice(0, 4).join(" ")} ${tr.dataset.late}`.toLowerCase();
  plant.keys.set(tr, [addressNumber(device.address), texts[1], Number(device.worker) || 0, state,
    Number(device.output_frequency_hz) || 0, texts[5], (device.class1_connections || 0) + (device.sessions || 0),
    device.faults || 0, (device.missed || 0) * 1e9 + (device.late || 0)]);
}

function showPlant(devices) {
  for (const device of devices) plantRow(device);
  const counts = new Map();
  let late = 0;
  for (const tr of plant.rows.values()) {
    counts.set(tr.dataset.state, (counts.get(tr.dataset.state) || 0) + 1);
    if (tr.dataset.late) late += 1;
  }
  const items = [...counts.entries()].sort((a, b) => b[1] - a[1]).map(([state, count]) => [state, count, state]);
  if (late) items.push(["missing productions", late, "late"]);
  // The summary's buttons are kept from one refresh to the next, their counts changed in place: a
  // button being clicked, or holding the keyboard's focus, is never swapped for a new one under it.
  // Only a new or vanished state (or a new order of the counts) lays the summary out again.
  const order = items.map(([, , filter]) => filter).join("\n");
  for (const [label, count, filter] of items) {
    let button = plant.summary.get(filter);
    if (button === undefined) {
      button = element("button", "", {type: "button", "data-filter": filter});
      button.addEventListener("click", () => { $("plant-filter").value = filter.toLowerCase(); filterPlant(); });
      plant.summary.set(filter, button);
    }
    const text = `${count} ${label}`;
    if (button.textContent !== text) button.textContent = text;
  }
  const total = `${plant.rows.size} devices:`;
  if (order !== plant.order || !plant.summaryTotal) {
    for (const filter of [...plant.summary.keys()]) if (!items.some((item) => item[2] === filter)) plant.summary.delete(filter);
    plant.summaryTotal = element("span", total);
    const parts = [plant.summaryTotal];
    for (const [, , filter] of items) parts.push(document.createTextNode(" "), plant.summary.get(filter));
    $("plant-summary").replaceChildren(...parts);
    plant.order = order;
  } else if (plant.summaryTotal.textContent !== total) {
    plant.summaryTotal.textContent = total;
  }
  sortPlant();
  filterPlant();
}

function sortPlant(column) {
  if (column !== undefined) {
    plant.descending = column === plant.sortColumn ? !plant.descending : false;
    plant.sortColumn = column;
  }
  const headings = $("plant-table").tHead.rows[0].cells;
  for (let i = 0; i < headings.length; i++) {
    headings[i].setAttribute("aria-sort", i === plant.sortColumn ? (plant.descending ? "descending" : "ascending") : "none");
  }
  const direction = plant.descending ? -1 : 1;
  const sorted = [...plant.rows.values()].sort((a, b) => {
    const x = plant.keys.get(a)[plant.sortColumn], y = plant.keys.get(b)[plant.sortColumn];
    const order = typeof x === "number" ? x - y : String(x).localeCompare(String(y));
    return direction * order || plant.keys.get(a)[0] - plant.keys.get(b)[0];
  });
  const body = $("plant-table").tBodies[0];
  // Moved only where the order changed: a refresh that changes nothing moves no row.
  sorted.forEach((tr, index) => { if (body.rows[index] !== tr) body.insertBefore(tr, body.rows[index] || null); });
}

async function openPlant(devices) {
  $("plant").hidden = false;
  $("title").textContent = `the plant: ${devices.length} devices`;
  $("plant-filter").addEventListener("input", filterPlant);
  [...$("plant-table").tHead.rows[0].cells].forEach((th, index) => {
    const button = element("button", th.textContent, {type: "button", class: "sort"});
    button.addEventListener("click", () => sortPlant(index));
    th.replaceChildren(button);
  });
  showPlant(devices);
  setLink(true);
  const poll = async () => {
    try { showPlant(await api("GET", "/plant")); setLink(true); } catch (error) { setLink(false); }
    setTimeout(poll, PLANT_REFRESH_MS);
  };
  poll();
}

function filterPlant() {
  const wanted = $("plant-filter").value.trim().toLowerCase();
  let shown = 0;
  for (const tr of plant.rows.values()) {
    tr.hidden = wanted !== "" && !tr.dataset.search.includes(wanted);
    if (!tr.hidden) shown += 1;
  }
  $("plant-shown").textContent = wanted ? `${shown} of ${plant.rows.size} shown` : "";
}

// -- which page ------------------------------------------------------------------------------------------------
function pageMessage(text) {
  const shown = $("page-message");
  shown.textContent = text;
  shown.hidden = false;
}

async function start() {
  const chosen = new URLSearchParams(location.search).get("device");
  let devices;
  try { devices = await api("GET", "/devices"); }
  catch (error) { setLink(false); $("link-state").textContent = error.message; return; }
  if (chosen !== null && !devices.some((device) => device.address === chosen)) {
    // A link to a device that is gone, or a typing error: say so, and list the devices there are.
    pageMessage(`There is no device ${JSON.stringify(chosen)} here (?device=${chosen}): ` +
                (devices.length ? "the devices this API serves are below." : "this API serves none."));
    return openPlant(devices);
  }
  if (chosen) return openPanel(chosen);
  if (devices.length === 1) return openPanel(devices[0].address);
  return openPlant(devices);
}

// Whatever fails on the way in is said on the page, not left as an unhandled rejection and a blank page.
start().catch((error) => { pageMessage(`The panel could not open: ${error.message}`); });
