// The preview page: input and result side by side as animated characters (three.js, vendored
// under ./vendor/three, loaded from this server only), on one timeline.
//
// It works before any model is served: the input clip (BVH, or a glTF character: .glb or
// .gltf with embedded buffers) is read and animated in the browser, and when a POST fails
// the problem+json detail is shown. The answer comes in the input's format (a GLB input
// gets its GLB back with the new animation), and Download saves it as it came.
//
// Where the service needs an API key (a 401), the page asks for one and sends it with each
// request as Authorization: Bearer; it is kept in sessionStorage (this tab), never in the URL.
//
// Tests read window.motionPreview: {webgl, styles, playing, time, duration, input: {loaded,
// frames, fps, frame, ticks, name, format}, result: {...}, download: {name, type, size,
// bytes, text (BVH only)}, lastMessage, needsKey}.

import * as THREE from './vendor/three/three.module.min.js';
import { BVHLoader } from './vendor/three/BVHLoader.js';
import { GLTFLoader } from './vendor/three/GLTFLoader.js';
import { OrbitControls } from './vendor/three/OrbitControls.js';

const $ = (id) => document.getElementById(id);

function hasWebGL() {
  try {
    const canvas = document.createElement('canvas');
    return Boolean(canvas.getContext('webgl2') || canvas.getContext('webgl'));
  } catch {
    return false;
  }
}

const state = {
  webgl: hasWebGL(),
  styles: { translator: [], fast: [], dance: [] },
  playing: true,
  time: 0,
  duration: 0,
  lastMessage: '',
  needsKey: false,
};
window.motionPreview = state;

// ---------------------------------------------------------------------------------------------
// The API key, when the service needs one

const KEY_STORAGE = 'motion-style-api-key';

function storedKey() {
  try {
    return sessionStorage.getItem(KEY_STORAGE) || '';
  } catch {
    return '';
  }
}

// fetch() with the stored key; a 401 shows the key form (the caller still gets the answer)
async function apiFetch(url, options = {}) {
  const headers = new Headers(options.headers || {});
  const key = storedKey();
  if (key) headers.set('Authorization', `Bearer ${key}`);
  const response = await fetch(url, { ...options, headers });
  if (response.status === 401) askForKey(Boolean(key));
  return response;
}

function askForKey(rejected) {
  state.needsKey = true;
  $('key-form').hidden = false;
  $('api-key').value = '';
  $('api-key').focus();
  say(rejected ? 'The service did not accept this API key: enter another.'
    : 'This service needs an API key: enter it above.', 'error');
}

function useKey(event) {
  event.preventDefault();
  const key = $('api-key').value.trim();
  if (!key) return;
  try {
    sessionStorage.setItem(KEY_STORAGE, key);
  } catch {
    say('This browser keeps no session storage: the key cannot be kept.', 'error');
    return;
  }
  $('api-key').value = '';
  $('key-form').hidden = true;
  state.needsKey = false;
  say('Key set.');
  loadStyles();
}

// ---------------------------------------------------------------------------------------------
// Reading clips: BVH text or glTF bytes, told apart by their first bytes (as the service does)

function isGltf(bytes) {
  const head = new TextDecoder().decode(bytes.slice(0, 4096)).replace(/^\uFEFF?\s*/, '');
  return new TextDecoder().decode(bytes.slice(0, 4)) === 'glTF'
    || (head.startsWith('{') && head.includes('"asset"'));
}

// BVHLoader logs to the console before it gives up on a file that is not BVH at all; a
// quick look at the first word keeps such files out of it.
function parseBvh(text) {
  if (!/^\uFEFF?\s*HIERARCHY\b/i.test(text)) {
    throw new Error('a BVH file starts with HIERARCHY');
  }
  const parsed = new BVHLoader().parse(text);
  if (!parsed.skeleton.bones.length || !parsed.clip.tracks.length) {
    throw new Error('no joints or no motion in it');
  }
  const root = parsed.skeleton.bones[0];
  return { object: root, clip: parsed.clip, bones: parsed.skeleton.bones, format: 'bvh' };
}

function parseGltf(bytes) {
  return new Promise((resolve, reject) => {
    new GLTFLoader().parse(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength), '',
      (gltf) => {
        const bones = [];
        gltf.scene.traverse((object) => { if (object.isBone) bones.push(object); });
        const clip = gltf.animations[0];
        if (!bones.length) reject(new Error('no skinned character in it'));
        else if (!clip || !clip.tracks.length) reject(new Error('no animation in it'));
        else resolve({ object: gltf.scene, clip, bones, format: 'glb' });
      },
      (error) => reject(new Error(error && error.message ? error.message : String(error))));
  });
}

// bytes (Uint8Array) of a clip -> {object, clip, bones, format}
async function parseClip(bytes) {
  if (isGltf(bytes)) return parseGltf(bytes);
  return parseBvh(new TextDecoder().decode(bytes));
}

// ---------------------------------------------------------------------------------------------
// One animated character in one viewport, posed at the shared time

class CharacterView {
  constructor(container, info) {
    this.container = container;
    this.info = info;
    this.state = {
      loaded: false, frames: 0, fps: 0, frame: 0, ticks: 0, name: '', format: '',
    };
    this.duration = 0;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1d2126);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 10000);
    this.camera.position.set(0, 150, 400);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.5);
    sun.position.set(1, 2, 1.5);
    this.scene.add(sun);
    this.mixer = null;
    this.action = null;
    this.object = null;
    this.helper = null;
    this.grid = null;
    this.renderer = null;
    if (state.webgl) {
      this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
      this.renderer.setPixelRatio(window.devicePixelRatio || 1);
      container.appendChild(this.renderer.domElement);
      this.controls = new OrbitControls(this.camera, this.renderer.domElement);
      this.controls.enableDamping = true;
      this.resize();
    } else {
      const note = document.createElement('p');
      note.className = 'note';
      note.textContent = 'This browser has no WebGL: the clip is read and played, not drawn.';
      container.appendChild(note);
    }
    this.placeholder = document.createElement('p');
    this.placeholder.className = 'placeholder';
    container.appendChild(this.placeholder);
  }

  resize() {
    if (!this.renderer) return;
    const width = Math.max(1, this.container.clientWidth);
    const height = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
  }

  setPlaceholder(text) {
    this.placeholder.textContent = text;
    this.placeholder.hidden = !text;
  }

  clear() {
    for (const part of [this.object, this.helper, this.grid]) if (part) this.scene.remove(part);
    if (this.mixer) this.mixer.stopAllAction();
    this.object = this.helper = this.grid = this.mixer = this.action = null;
    this.duration = 0;
    Object.assign(this.state, {
      loaded: false, frames: 0, fps: 0, frame: 0, name: '', format: '',
    });
    this.info.textContent = '';
  }

  // parsed: what parseClip returns.
  show(parsed, name) {
    this.clear();
    const times = parsed.clip.tracks.reduce(
      (longest, track) => (track.times.length > longest.length ? track.times : longest), [0],
    );
    const frames = times.length;
    const frameTime = frames > 1 ? times[1] - times[0] : 1 / 30;
    this.object = parsed.object;
    this.scene.add(this.object);
    this.helper = new THREE.SkeletonHelper(this.object);
    this.helper.material.linewidth = 2;
    this.helper.material.depthTest = false;  // the bones show through the mesh
    this.scene.add(this.helper);
    this.mixer = new THREE.AnimationMixer(this.object);
    this.action = this.mixer.clipAction(parsed.clip);
    this.action.play();
    this.bones = parsed.bones;
    this.frameTime = frameTime;
    this.start = times[0];
    this.duration = parsed.clip.duration;
    Object.assign(this.state, {
      loaded: true, frames, fps: Math.round(1 / frameTime), frame: 0, name, format: parsed.format,
    });
    this.info.textContent = `${name}: ${frames} frames at ${this.state.fps} fps, `
      + `${parsed.bones.length} bones`;
    this.setPlaceholder('');
    this.frame();
  }

  // Pose at time t (seconds on the shared timeline; held at the end after the clip ends).
  seek(t) {
    if (!this.action) return;
    this.action.time = Math.max(0, Math.min(t, this.duration - 1e-6));
    this.mixer.update(0);
    const frame = Math.floor((this.action.time - this.start) / this.frameTime + 1e-6);
    this.state.frame = Math.min(this.state.frames - 1, Math.max(0, frame));
  }

  // Fit the camera to the space the character moves through (its bones over the clip), so
  // it fills the view whatever the clip's units.
  frame() {
    const box = new THREE.Box3();
    const point = new THREE.Vector3();
    for (let i = 0; i <= 16; i += 1) {
      this.seek((this.duration * i) / 16);
      this.object.updateMatrixWorld(true);
      for (const bone of this.bones) box.expandByPoint(bone.getWorldPosition(point));
    }
    this.seek(0);
    const size = box.getSize(new THREE.Vector3());
    const centre = box.getCenter(new THREE.Vector3());
    const extent = Math.max(size.x, size.y, size.z, 1e-3);
    this.grid = new THREE.GridHelper(extent * 2, 20, 0x556070, 0x343a42);
    this.grid.position.set(centre.x, box.min.y, centre.z);
    this.scene.add(this.grid);
    // far enough for the box's bounding sphere to fit the vertical field of view, a margin
    const radius = Math.max(size.length() / 2, 1e-3);
    const distance = (radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2))) * 0.85;
    const direction = new THREE.Vector3(0.35, 0.2, 1).normalize();
    this.camera.near = distance / 100;
    this.camera.far = distance * 100;
    this.camera.position.copy(centre).addScaledVector(direction, distance);
    this.camera.updateProjectionMatrix();
    if (this.controls) {
      this.controls.target.copy(centre);
      this.controls.update();
    } else {
      this.camera.lookAt(centre);
    }
  }

  render() {
    this.state.ticks += 1;
    if (this.renderer) {
      if (this.controls) this.controls.update();
      this.renderer.render(this.scene, this.camera);
    }
  }
}

const inputView = new CharacterView($('input-view'), $('input-info'));
const resultView = new CharacterView($('result-view'), $('result-info'));
state.input = inputView.state;
state.result = resultView.state;
inputView.setPlaceholder('Choose a BVH or GLB clip to see it here.');
resultView.setPlaceholder('Press Run to see the styled clip here.');

// ---------------------------------------------------------------------------------------------
// One timeline for both views: play/pause, scrub, loop over the longer clip

const TIMELINE_STEPS = 1000;

function updateDuration() {
  state.duration = Math.max(inputView.duration, resultView.duration);
  $('timeline').disabled = !state.duration;
  showTime();
}

function showTime() {
  const { time, duration } = state;
  $('time').textContent = `${time.toFixed(2)} / ${duration.toFixed(2)} s`;
  $('timeline').value = String(duration ? Math.round((time / duration) * TIMELINE_STEPS) : 0);
}

function seekAll(time) {
  state.time = time;
  inputView.seek(time);
  resultView.seek(time);
  showTime();
}

function setPlaying(playing) {
  state.playing = playing;
  const button = $('play');
  button.textContent = playing ? 'Pause' : 'Play';
  button.setAttribute('aria-pressed', String(!playing));
}

const clock = new THREE.Clock();
function animate() {
  const dt = Math.min(clock.getDelta(), 0.1);
  if (state.playing && state.duration > 0) {
    let time = state.time + dt;
    if (time > state.duration) time = 0;  // both start again together
    seekAll(time);
  }
  inputView.render();
  resultView.render();
  requestAnimationFrame(animate);
}
requestAnimationFrame(animate);
window.addEventListener('resize', () => {
  inputView.resize();
  resultView.resize();
});

// ---------------------------------------------------------------------------------------------
// Messages

function say(text, kind = 'info') {
  const box = $('message');
  box.textContent = text;
  box.className = kind;
  state.lastMessage = text;
}

// Text for a failed response: the problem+json title, status and detail when there is one.
async function describeFailure(response) {
  const type = response.headers.get('content-type') || '';
  if (type.includes('json')) {
    try {
      const problem = await response.json();
      const parts = [`${problem.title || response.statusText} (${problem.status || response.status})`];
      if (problem.detail) parts.push(problem.detail);
      if (problem.limit !== undefined) parts.push(`limit: ${problem.limit}`);
      if (problem.request_id) parts.push(`request id ${problem.request_id}`);
      return parts.join(' - ');
    } catch {
      // fall through to the status line
    }
  }
  return `HTTP ${response.status} ${response.statusText}`.trim();
}

// ---------------------------------------------------------------------------------------------
// Styles, grouped by family: the translator's shipped styles, the ones registered from a
// studio's clips (POST /v1/styles), the fast networks

const GROUPS = [
  { key: 'translator', label: 'translator: any clip', pick: (s) => !s.registered },
  { key: 'registered', label: 'registered from your clips', pick: (s) => s.registered },
  { key: 'fast', label: 'fast networks', pick: () => true },
];

function familyOf(group) {
  return group === 'fast' ? 'fast' : 'translator';
}

// A style as a request names it: bare, or library:style where two models of its family
// offer the name (the service refuses the bare name then as ambiguous)
function requestName(style, family) {
  const sharing = (state.styles[family] || []).filter((s) => s.name === style.name);
  return sharing.length > 1 && style.qualified_name ? style.qualified_name : style.name;
}

function styleNames() {
  const names = new Set();
  for (const family of ['translator', 'fast']) {
    for (const style of state.styles[family] || []) names.add(requestName(style, family));
  }
  return [...names].sort();
}

async function loadStyles() {
  const select = $('style-name');
  try {
    const response = await apiFetch('/v1/styles', { headers: { Accept: 'application/json' } });
    if (!response.ok) throw new Error(await describeFailure(response));
    state.styles = await response.json();
  } catch (error) {
    if (!state.needsKey) say(`Could not list the styles: ${error.message}`, 'error');
  }
  select.replaceChildren();
  let count = 0;
  for (const group of GROUPS) {
    const styles = (state.styles[familyOf(group.key)] || []).filter(group.pick);
    if (!styles.length) continue;
    const optgroup = document.createElement('optgroup');
    optgroup.label = group.label;
    optgroup.dataset.group = group.key;
    for (const style of styles) {
      const name = requestName(style, familyOf(group.key));
      const option = new Option(
        style.clips ? `${name} (${style.clips} clip${style.clips === 1 ? "" : "s"})` : name,
        name,
      );
      option.dataset.family = familyOf(group.key);
      optgroup.appendChild(option);
      count += 1;
    }
    select.appendChild(optgroup);
  }
  if (!count) select.appendChild(new Option('(no styles are served yet)', ''));
  const list = $('style-names');
  list.replaceChildren(...styleNames().map((name) => new Option(name, name)));
  const genre = $('genre');
  genre.replaceChildren(new Option('(predict from the music)', ''));
  for (const style of state.styles.dance || []) genre.appendChild(new Option(style.name, style.name));
}

function addMixRow(name = '', weight = 0.5) {
  const row = document.createElement('div');
  row.className = 'mix-row';
  const nameInput = document.createElement('input');
  nameInput.type = 'text';
  nameInput.placeholder = 'style name';
  nameInput.setAttribute('list', 'style-names');
  nameInput.value = name;
  nameInput.className = 'mix-name';
  const weightInput = document.createElement('input');
  weightInput.type = 'number';
  weightInput.min = '0';
  weightInput.step = '0.05';
  weightInput.value = String(weight);
  weightInput.className = 'mix-weight';
  const remove = document.createElement('button');
  remove.type = 'button';
  remove.textContent = 'remove';
  remove.addEventListener('click', () => row.remove());
  row.append(nameInput, weightInput, remove);
  $('mix-rows').appendChild(row);
}

function mixWeights() {
  const weights = {};
  for (const row of document.querySelectorAll('.mix-row')) {
    const name = row.querySelector('.mix-name').value.trim();
    const weight = Number(row.querySelector('.mix-weight').value);
    if (name) weights[name] = (weights[name] || 0) + (Number.isFinite(weight) ? weight : 0);
  }
  return weights;
}

// ---------------------------------------------------------------------------------------------
// Input clip

async function showInput() {
  const file = $('content-file').files[0];
  if (!file) {
    inputView.clear();
    inputView.setPlaceholder('Choose a BVH or GLB clip to see it here.');
    updateDuration();
    return;
  }
  try {
    inputView.show(await parseClip(new Uint8Array(await file.arrayBuffer())), file.name);
    say(`${file.name} loaded: pick a style and press Run.`);
  } catch (error) {
    inputView.clear();
    inputView.setPlaceholder('This file could not be read as BVH or glTF.');
    say(`Could not read ${file.name} as BVH or glTF: ${error.message}`, 'error');
  }
  updateDuration();
  seekAll(0);
}

// ---------------------------------------------------------------------------------------------
// Run

function selectedMode() {
  return document.querySelector('input[name="mode"]:checked').value;
}

// {url, form} for the chosen inputs, or a string saying what is missing.
function buildRequest() {
  const mode = selectedMode();
  const content = $('content-file').files[0];
  const form = new FormData();
  const strength = $('strength').value;
  if (mode === 'music') {
    const audio = $('audio-file').files[0];
    if (!audio) return 'Choose a music file first.';
    form.append('audio', audio);
    if ($('genre').value) form.append('genre', $('genre').value);
    if (content) form.append('skeleton', content);
    return { url: '/v1/dance', form };
  }
  if (!content) return 'Choose a content clip (BVH or GLB) first.';
  form.append('content', content);
  if (mode === 'name') {
    const option = $('style-name').selectedOptions[0];
    const name = option ? option.value : '';
    form.append('style_name', name);
    if (option && option.dataset.family === 'fast') return { url: '/v1/stylize', form };
    form.append('strength', strength);
    return { url: '/v1/transfer', form };
  }
  if (mode === 'clip') {
    const style = $('style-file').files[0];
    if (!style) return 'Choose a style clip (BVH or GLB) first.';
    form.append('style', style);
  } else if (mode === 'keypoints') {
    const keypoints = $('keypoints-file').files[0];
    if (!keypoints) return 'Choose a keypoints zip or JSON file first.';
    form.append('keypoints', keypoints);
  } else if (mode === 'mix') {
    const weights = mixWeights();
    if (!Object.keys(weights).length) return 'Add at least one style to the mix.';
    form.append('style_mix', JSON.stringify(weights));
  }
  form.append('strength', strength);
  return { url: '/v1/transfer', form };
}

// The service's warnings of an answer: X-Warnings, a JSON array of strings.
function warningsOf(response) {
  const header = response.headers.get('x-warnings');
  if (!header) return [];
  try {
    const said = JSON.parse(header);
    return Array.isArray(said) ? said.map(String) : [header];
  } catch {
    return [header];
  }
}

function filenameOf(response, fallback) {
  const disposition = response.headers.get('content-disposition') || '';
  const match = /filename\*?=(?:UTF-8'')?"?([^";]+)"?/i.exec(disposition);
  return match ? decodeURIComponent(match[1]) : fallback;
}

let downloadUrl = null;

async function run(event) {
  event.preventDefault();
  const request = buildRequest();
  if (typeof request === 'string') {
    say(request, 'error');
    return;
  }
  const button = $('run');
  button.disabled = true;
  $('download').hidden = true;  // an earlier result must not pass for this run's
  state.download = null;
  say(`Running ${request.url}...`);
  try {
    // no ?format: the answer comes in the input's format (a GLB input gets its GLB back)
    const response = await apiFetch(request.url, {
      method: 'POST',
      body: request.form,
      headers: { Accept: 'text/plain, model/gltf-binary, application/problem+json' },
    });
    if (!response.ok) {
      if (response.status !== 401) {  // a 401 has asked for a key already
        say(`${request.url} failed: ${await describeFailure(response)}`, 'error');
      }
      return;
    }
    const type = (response.headers.get('content-type') || 'text/plain').split(';')[0];
    const bytes = new Uint8Array(await response.arrayBuffer());
    const name = filenameOf(response, type === 'model/gltf-binary' ? 'result.glb' : 'result.bvh');
    resultView.show(await parseClip(bytes), name);
    updateDuration();
    seekAll(0);
    if (downloadUrl) URL.revokeObjectURL(downloadUrl);
    downloadUrl = URL.createObjectURL(new Blob([bytes], { type }));
    // what the download button saves (read by tests)
    state.download = { name, type, size: bytes.length, bytes };
    if (type !== 'model/gltf-binary') state.download.text = new TextDecoder().decode(bytes);
    const link = $('download');
    link.href = downloadUrl;
    link.download = name;
    link.textContent = `Download ${name.split('.').pop().toUpperCase()}`;
    link.hidden = false;
    const timing = response.headers.get('server-timing');
    const genre = response.headers.get('x-dance-genre');
    const danced = genre ? `, ${genre} at ${response.headers.get('x-dance-tempo')} bpm` : '';
    const warnings = warningsOf(response);
    say(`Done: ${response.headers.get('x-frames') || resultView.state.frames} frames${danced}`
      + (timing ? ` (${timing})` : '') + warnings.map((w) => `\nWarning: ${w}`).join(''),
    warnings.length ? 'warning' : 'info');
  } catch (error) {
    say(`${request.url} failed: ${error.message}`, 'error');
  } finally {
    button.disabled = false;
  }
}

// ---------------------------------------------------------------------------------------------
// Wiring

$('key-form').addEventListener('submit', useKey);
$('content-file').addEventListener('change', showInput);
$('controls').addEventListener('submit', run);
$('mix-add').addEventListener('click', () => addMixRow());
$('strength').addEventListener('input', () => {
  $('strength-value').textContent = Number($('strength').value).toFixed(2);
});
$('play').addEventListener('click', () => setPlaying(!state.playing));
$('timeline').addEventListener('input', () => {
  seekAll((Number($('timeline').value) / TIMELINE_STEPS) * state.duration);
});
for (const [id, mode] of [['style-name', 'name'], ['style-file', 'clip'],
  ['keypoints-file', 'keypoints'], ['audio-file', 'music'], ['genre', 'music']]) {
  $(id).addEventListener('change', () => {
    document.querySelector(`input[name="mode"][value="${mode}"]`).checked = true;
  });
}
setPlaying(true);
updateDuration();
addMixRow();
addMixRow('', 0.5);
loadStyles();
if ($('content-file').files[0]) showInput(); // a file kept by the browser across reloads
