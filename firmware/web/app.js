// caphub's web page: the hub's live state and poses (Server-Sent Events), its commands and its
// takes, through the HTTP API of `caphub serve` (docs/serve.md). Plain JavaScript, no build step;
// three.js (global THREE) comes from the hub's /three/three.min.js.
'use strict';

const $ = (id) => document.getElementById(id);
let csrf = '';
let skeleton = null;
let state = null;

function showMessage(text) {
  $('message').textContent = text || '';
}

async function call(method, path, body) {
  const r = await fetch(path, {
    method,
    credentials: 'same-origin',
    headers: { 'Content-Type': 'application/json', 'X-CSRF-Token': csrf },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const j = await r.json().catch(() => ({}));
  if (!r.ok) {
    throw new Error(j.error || `${r.status} ${r.statusText}`);
  }
  return j;
}

// Runs a command from a button; its error goes to the message line.
function action(button, fn) {
  $(button).addEventListener('click', async () => {
    $(button).disabled = true;
    try {
      showMessage('');
      await fn();
    } catch (e) {
      showMessage(e.message);
    } finally {
      $(button).disabled = false;
    }
  });
}

// ---- session ------------------------------------------------------------------------------

async function startSession() {
  const s = await call('GET', '/api/session');
  $('board').textContent = `${s.board} - ${s.version}`;
  if (s.authenticated) {
    csrf = s.csrf;
  } else if (!s.password_required) {
    csrf = (await call('POST', '/api/login', {})).csrf;
  } else {
    $('login').hidden = false;
    return;
  }
  await startApp();
}

$('login-form').addEventListener('submit', async (ev) => {
  ev.preventDefault();
  try {
    csrf = (await call('POST', '/api/login', { password: $('password').value })).csrf;
    $('login').hidden = true;
    await startApp();
  } catch (e) {
    $('login-error').textContent = e.message;
  }
});

async function startApp() {
  $('app').hidden = false;
  skeleton = await call('GET', '/api/skeleton');
  view.init($('view'));
  const events = new EventSource('/api/events');
  events.onmessage = (ev) => showState(JSON.parse(ev.data));
  events.onopen = () => setLink(true);
  events.onerror = () => setLink(false);
  const poses = new EventSource('/api/poses');
  poses.onmessage = (ev) => view.pose(JSON.parse(ev.data));
  await refreshTakes();
}

function setLink(ok) {
  $('link').textContent = ok ? 'live' : 'reconnecting';
  $('link').className = ok ? 'pill ok' : 'pill bad';
}

// ---- state --------------------------------------------------------------------------------

function fmt(x, digits = 1) {
  return typeof x === 'number' ? x.toFixed(digits) : '-';
}

function bytes(n) {
  if (n >= 1 << 20) return `${(n / (1 << 20)).toFixed(1)} MiB`;
  if (n >= 1 << 10) return `${(n / (1 << 10)).toFixed(1)} KiB`;
  return `${n} B`;
}

let lastTake = null;

// A gyroscope-only heading: what its online hard-iron estimate waits for (docs/serve.md).
function headingDetail(l) {
  if (l.waiting_for === 'readings') {
    const got = Math.floor(l.readings_s);
    return got < l.needed_s ? `learning, ${got} of ${fmt(l.needed_s, 0)} s`
      : 'learning, solving';  // solved about once a second
  }
  if (l.waiting_for === 'turns') {
    return l.spread === undefined ? 'turn it' : `turn it (spread ${fmt(l.spread, 3)} of ${fmt(l.needed_spread, 3)})`;
  }
  if (l.waiting_for === 'a steadier field') return `field unsteady (residual ${fmt(l.residual_pct)} %)`;
  return 'measuring its heading';
}

// The heading cell: the mode, and for a gyro-only one what it waits for (hidden at phone width,
// where the body calibration card says what to do).
function headingCell(x) {
  const td = document.createElement('td');
  td.textContent = x.heading ?? '';
  if (x.heading && x.heading_learning) {
    const detail = document.createElement('span');
    detail.className = 'detail';
    detail.textContent = `: ${headingDetail(x.heading_learning)}`
      + (x.joint_turn_deg === undefined ? '' : `; strap set from the joints (${x.joint_turn_deg > 0 ? '+' : ''}${fmt(x.joint_turn_deg)} deg)`);
    td.appendChild(detail);
  }
  return td;
}

function showState(s) {
  state = s;
  const rows = s.sensors.map((x) => {
    const tr = document.createElement('tr');
    if (!x.online) tr.className = 'off';
    for (const v of [x.name, x.segment, fmt(x.rate_hz), x.lost, x.read_errors,
                     x.gyro_clip_events ?? 0]) {
      const td = document.createElement('td');
      td.textContent = v;
      tr.appendChild(td);
    }
    tr.appendChild(headingCell(x));
    return tr;
  });
  $('sensors').tBodies[0].replaceChildren(...rows);
  const lat = s.latency_ms ? `sample p50 ${fmt(s.latency_ms.p50, 2)} / p99 ${fmt(s.latency_ms.p99, 2)} ms` : '';
  const pl = s.pose_latency_ms ? `; pose p50 ${fmt(s.pose_latency_ms.p50, 2)} / p99 ${fmt(s.pose_latency_ms.p99, 2)} ms` : '';
  $('latency').textContent = lat + pl;
  showSensorCalibration(s);

  if (s.take) {
    const r = s.recording || {};
    $('take-status').textContent = `recording ${s.take.file}: ${r.records ?? s.take.records} records, ${bytes(r.bytes || 0)}${s.take.error ? ' - ' + s.take.error : ''}`;
  } else {
    $('take-status').textContent = `no take (${s.takes_recorded} recorded since start)`;
  }
  $('take-stop').disabled = !s.take;
  $('marker').disabled = !s.take;
  const takeNow = s.take ? s.take.file : null;
  if (takeNow !== lastTake) {
    lastTake = takeNow;
    refreshTakes();
  }
  $('recording').textContent = s.export ? `exporting ${s.export.take} (${s.export.format}): ${s.export.stage} ${Math.round(100 * s.export.fraction)} %` : '';

  const b = s.body;
  let text = b.calibrated && b.calibration !== 'none' ? `calibrated (${b.calibration})`
    : (b.calibrated || b.calibration === 'not calibrated' ? 'not calibrated: nominal mountings' : b.calibration);
  const req = b.request;
  const cd = b.countdown || {};
  if (req.state === 'averaging' || req.state === 'not started') {
    if (cd.t_in_s > 0) text = `T-pose in ${Math.ceil(cd.t_in_s)} s`;
    else if (cd.n_in_s > 0 && cd.kind === 'npose') text = `N-pose in ${Math.ceil(cd.n_in_s)} s`;
    else if (cd.n_in_s > 0) text = `hold the T-pose; N-pose in ${Math.ceil(cd.n_in_s)} s`;
    if (req.state === 'averaging') text += ` - averaging ${Math.round(100 * req.progress)} %`;
  } else if (req.state === 'failed') {
    text = `calibration failed: ${req.message}`;
  }
  $('cal-status').textContent = text;
  // Sensors with no magnetic heading yet: a body calibration cannot tell how their straps are
  // turned about the vertical; the joints set them against each other once the body moves, and
  // the online estimate corrects each once it has measured its heading (docs/body-calibration.md,
  // "Free headings", "Headings from the joints").
  const free = s.sensors.filter((x) => x.online && x.heading === 'gyro-only').map((x) => x.name);
  $('cal-heading-hint').textContent = free.length === 0 ? ''
    : `${free.length} sensor${free.length > 1 ? 's have' : ' has'} no magnetic heading yet (${free.join(', ')}): `
      + 'a body calibration cannot tell how their straps are turned about the vertical. After it, '
      + 'walk a few steps, swinging the arms: the joints set the straps against each other (the '
      + 'sensor table says so), and the online estimate corrects each heading once it has measured '
      + 'it. Turning each limb through different directions until the table reads '
      + 'online-hard-iron, or calibrating the magnetometers (Sensor calibration, step 3), '
      + 'measures them before the calibration.';
  const hr = b.heading_reset || {};
  $('heading-status').textContent =
    hr.state === 'pending' ? 'heading reset: waiting for the capture to reach it'
    : hr.state === 'done' ? `heading reset: done (the capture heading turned to ${hr.heading_deg.toFixed(1)} deg)`
    : hr.state === 'failed' ? hr.message : '';
}

// ---- commands -----------------------------------------------------------------------------

action('take-start', async () => {
  await call('POST', '/api/take/start', { name: $('take-name').value });
  await refreshTakes();
});
action('take-stop', async () => {
  await call('POST', '/api/take/stop', {});
  await refreshTakes();
});
action('marker', () => call('POST', '/api/take/marker', { label: $('marker-label').value }));
action('calibrate', () => {
  const t = Number($('cal-countdown').value) || 0;
  return call('POST', '/api/calibrate', { pose: $('cal-pose').value, countdown_s: t, n_countdown_s: t + 8 });
});
action('heading-reset', () => call('POST', '/api/heading-reset', {}));

// ---- sensor calibration -------------------------------------------------------------------

const kindText = { gyro: 'gyroscopes', accel: 'accelerometers', mag: 'magnetometers' };

function showSensorCalibration(s) {
  const c = s.sensor_calibration_session || {};
  const inForce = s.sensor_calibration ? `in force: ${s.sensor_calibration}` : 'in force: none (nominal sensors)';
  const saved = c.saved && c.saved !== s.sensor_calibration ? `; saved ${c.saved}, applied ${c.applies}` :
    (c.saved ? `; updated, applied ${c.applies}` : '');
  $('sensor-calibration').textContent = `sensor calibration ${inForce}${saved}`;
  const p = c.procedure;
  for (const id of ['scal-gyro', 'scal-accel', 'scal-mag']) $(id).disabled = !!c.running;
  $('scal-cancel').disabled = !c.running;
  if (!p) {
    $('scal-instruction').textContent = c.virtual_suit ? 'Virtual suit: the subject does each motion when asked.' : '';
    return;
  }
  $('scal-instruction').textContent = `${kindText[p.kind] || p.kind}: ${p.instruction}`;
  $('scal-step').textContent = p.step ? `${p.stage} - ${p.step}` : p.stage;
  $('scal-progress').value = p.progress || 0;
  const r = p.result;
  if (!r) {
    $('scal-result').textContent = '';
    return;
  }
  const q = r.quality || {};
  const failed = (r.sensors || []).filter((x) => !x.ok).map((x) => `${x.name}: ${x.error}`);
  $('scal-result').textContent = `${r.calibrated} of ${r.sensors_total} sensors calibrated; quality: ${q.figure} ` +
    `${fmt(q.value, 3)} ${q.unit}${q.coverage !== undefined ? `, coverage ${fmt(100 * q.coverage, 0)} %` : ''}` +
    (failed.length ? `; not calibrated: ${failed.join('; ')}` : '');
}

const startSensorCalibration = (kind, extra = {}) => call('POST', '/api/sensor-calibration', { kind, ...extra });
action('scal-gyro', () => startSensorCalibration('gyro'));
action('scal-accel', () => startSensorCalibration('accel', { positions: Number($('scal-positions').value) }));
action('scal-mag', () => startSensorCalibration('mag'));
action('scal-cancel', () => call('POST', '/api/sensor-calibration/cancel', {}));
$('show-preview').addEventListener('change', () => {
  const img = $('preview');
  img.hidden = !$('show-preview').checked;
  img.src = img.hidden ? '' : '/api/preview.mjpeg';
});

// ---- takes --------------------------------------------------------------------------------

function exportQuery(format) {
  const q = new URLSearchParams({ format, names: $('exp-names').value });
  if (format === 'bvh' || format === 'csv') q.set('units', $('exp-units').value);
  if ($('exp-rate').value) q.set('rate', $('exp-rate').value);
  return q.toString();
}

async function refreshTakes() {
  let list;
  try {
    list = (await call('GET', '/api/takes')).takes;
  } catch (e) {
    showMessage(e.message);
    return;
  }
  const rows = list.map((t) => {
    const tr = document.createElement('tr');
    tr.dataset.file = t.file;
    const name = document.createElement('td');
    name.textContent = t.file + (t.recording ? ' (recording)' : '') + (t.markers ? ` - ${t.markers} markers` : '');
    name.title = 'show its summary';
    name.style.cursor = 'pointer';
    name.addEventListener('click', () => {
      $('take-info').hidden = !t.info;
      $('take-info').textContent = t.info || '';
    });
    const len = document.createElement('td');
    len.textContent = t.duration_s !== undefined ? `${fmt(t.duration_s)} s` : '';
    const size = document.createElement('td');
    size.textContent = bytes(t.bytes);
    const dl = document.createElement('td');
    const base = `/api/takes/${encodeURIComponent(t.file)}`;
    const link = (label, href, cls) => {
      const a = document.createElement('a');
      a.textContent = label;
      a.href = href;
      a.className = cls;
      a.setAttribute('download', '');
      dl.appendChild(a);
      return a;
    };
    link('cap', `${base}/raw`, 'dl-cap');
    if (!t.recording) {
      for (const f of ['bvh', 'glb', 'csv', 'sto']) {
        const a = link(f, `${base}/export?${exportQuery(f)}`, `dl-${f}`);
        // The options chosen above at the moment of the click.
        a.addEventListener('click', () => { a.href = `${base}/export?${exportQuery(f)}`; });
      }
    }
    const del = document.createElement('td');
    if (!t.recording) {
      const b = document.createElement('button');
      b.textContent = 'delete';
      b.className = 'danger';
      b.addEventListener('click', async () => {
        const typed = window.prompt(`Delete ${t.file} for good? Type its name to confirm:`);
        if (typed === null) return;
        try {
          await call('POST', `${base}/delete`, { confirm: typed });
          await refreshTakes();
        } catch (e) {
          showMessage(e.message);
        }
      });
      del.appendChild(b);
    }
    tr.append(name, len, size, dl, del);
    return tr;
  });
  $('takes').tBodies[0].replaceChildren(...rows);
}

// ---- 3D view ------------------------------------------------------------------------------

// The skeleton as boxes between joint centres (and to the end sites), in the hub's world frame
// (Y up, metres); the camera follows the pelvis so the body stays in frame wherever it walks.
const view = {
  poses: 0,
  init(el) {
    this.el = el;
    const n = skeleton.segments.length;
    this.bones = [];
    for (let i = 0; i < n; ++i) {
      if (skeleton.segments[i].parent >= 0) this.bones.push({ from: skeleton.segments[i].parent, to: i });
    }
    for (const e of skeleton.end_sites) this.bones.push({ from: e.segment, end: e });
    try {
      if (typeof THREE === 'undefined') throw new Error('three.js not loaded');
      this.initWebGL();
      el.dataset.renderer = 'webgl';
    } catch (e) {
      // No WebGL (an old phone, a browser without a GPU): the same skeleton drawn in 2D.
      this.gl = null;
      this.canvas = document.createElement('canvas');
      el.appendChild(this.canvas);
      el.dataset.renderer = '2d';
    }
    window.addEventListener('resize', () => this.resize());
    this.resize();
  },
  initWebGL() {
    const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.gl = renderer;
    this.el.appendChild(renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x0f172a);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);
    const grid = new THREE.GridHelper(20, 40, 0x64748b, 0x334155);
    this.scene.add(grid);
    const material = new THREE.MeshNormalMaterial();
    const box = new THREE.BoxBufferGeometry(1, 1, 1);
    this.meshes = this.bones.map(() => {
      const m = new THREE.Mesh(box, material);
      this.scene.add(m);
      return m;
    });
    const ball = new THREE.SphereBufferGeometry(0.035, 12, 8);
    const jointMaterial = new THREE.MeshBasicMaterial({ color: 0xf8fafc });
    this.joints = skeleton.segments.map(() => {
      const m = new THREE.Mesh(ball, jointMaterial);
      this.scene.add(m);
      return m;
    });
    this.target = new THREE.Vector3(0, 1, 0);
  },
  resize() {
    const w = this.el.clientWidth;
    const h = this.el.clientHeight;
    if (this.gl) {
      this.gl.setPixelRatio(window.devicePixelRatio || 1);
      this.gl.setSize(w, h, false);
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
    } else {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    if (this.last) this.draw(this.last);
  },
  // End site of bone b in the world: its segment's centre plus the offset turned by its rotation.
  endPoint(p, e) {
    const [w, x, y, z] = p.q[e.segment];
    const [vx, vy, vz] = e.offset;
    // v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    const cx = y * vz - z * vy, cy = z * vx - x * vz, cz = x * vy - y * vx;
    const ex = y * cz - z * cy, ey = z * cx - x * cz, ez = x * cy - y * cx;
    const c = p.p[e.segment];
    return [c[0] + vx + 2 * (w * cx + ex), c[1] + vy + 2 * (w * cy + ey), c[2] + vz + 2 * (w * cz + ez)];
  },
  // A pose from the stream: drawn at the browser's next frame, the newest one if several came
  // in between, so that a slow device (software WebGL, a phone) draws what it can and stays
  // responsive instead of queueing a draw per pose.
  pose(p) {
    this.last = p;
    if (!this.frameRequested) {
      this.frameRequested = true;
      requestAnimationFrame(() => {
        this.frameRequested = false;
        this.draw(this.last);
      });
    }
  },
  draw(p) {
    this.poses += 1;
    this.el.dataset.poses = String(this.poses);
    $('pose-info').textContent = `pose ${p.serial}${p.calibrated ? '' : ' (nominal mountings)'}`;
    const ends = this.bones.map((b) => [p.p[b.from], b.end ? this.endPoint(p, b.end) : p.p[b.to]]);
    const root = p.p[0];
    if (this.gl) {
      const up = new THREE.Vector3(0, 1, 0);
      ends.forEach(([a, b], i) => {
        const va = new THREE.Vector3(...a);
        const vb = new THREE.Vector3(...b);
        const d = vb.clone().sub(va);
        const len = Math.max(d.length(), 1e-3);
        const m = this.meshes[i];
        m.position.copy(va).add(vb).multiplyScalar(0.5);
        m.quaternion.setFromUnitVectors(up, d.divideScalar(len));
        m.scale.set(0.05, len, 0.05);
      });
      p.p.forEach((c, i) => this.joints[i].position.set(...c));
      this.target.lerp(new THREE.Vector3(root[0], root[1], root[2]), 0.2);
      this.camera.position.set(this.target.x + 1.6, this.target.y + 0.6, this.target.z + 3.2);
      this.camera.lookAt(this.target);
      this.gl.render(this.scene, this.camera);
    } else {
      const g = this.canvas.getContext('2d');
      const w = this.canvas.width, h = this.canvas.height;
      g.fillStyle = '#0f172a';
      g.fillRect(0, 0, w, h);
      const s = h / 2.4;
      const px = (v) => [w / 2 + (v[0] - root[0] + 0.5 * (v[2] - root[2])) * s, h * 0.9 - v[1] * s];
      g.strokeStyle = '#38bdf8';
      g.lineWidth = 4;
      g.beginPath();
      for (const [a, b] of ends) {
        g.moveTo(...px(a));
        g.lineTo(...px(b));
      }
      g.stroke();
    }
  },
};

startSession().catch((e) => showMessage(e.message));
