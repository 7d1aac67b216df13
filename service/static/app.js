// The preview page: input and result side by side as animated skeletons (three.js, vendored
// under ./vendor/three, loaded from this server only).
//
// It works before any model is served: the input clip is parsed and animated in the browser,
// and when a POST fails the problem+json detail is shown. Tests read window.motionPreview:
// {webgl, styles, input: {loaded, frames, fps, frame, ticks}, result: {...}, download: {name,
// text}, lastMessage}.

import * as THREE from './vendor/three/three.module.min.js';
import { BVHLoader } from './vendor/three/BVHLoader.js';
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
  lastMessage: '',
};
window.motionPreview = state;

// ---------------------------------------------------------------------------------------------
// One animated skeleton in one viewport

class SkeletonView {
  constructor(container, info) {
    this.container = container;
    this.info = info;
    this.state = { loaded: false, frames: 0, fps: 0, frame: 0, ticks: 0, name: '' };
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1d2126);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.1, 10000);
    this.camera.position.set(0, 150, 400);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2));
    this.mixer = null;
    this.action = null;
    this.root = null;
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
    if (this.root) this.scene.remove(this.root);
    if (this.helper) this.scene.remove(this.helper);
    if (this.grid) this.scene.remove(this.grid);
    if (this.mixer) this.mixer.stopAllAction();
    this.root = this.helper = this.grid = this.mixer = this.action = null;
    Object.assign(this.state, { loaded: false, frames: 0, fps: 0, frame: 0, name: '' });
    this.info.textContent = '';
  }

  // parsed: what BVHLoader.parse returns ({skeleton, clip}).
  show(parsed, name) {
    this.clear();
    const track = parsed.clip.tracks[0];
    const times = track ? track.times : [0];
    const frames = times.length;
    const frameTime = frames > 1 ? times[1] - times[0] : 1 / 30;
    this.root = parsed.skeleton.bones[0];
    this.scene.add(this.root);
    this.helper = new THREE.SkeletonHelper(this.root);
    this.helper.material.linewidth = 2;
    this.scene.add(this.helper);
    this.mixer = new THREE.AnimationMixer(this.root);
    this.action = this.mixer.clipAction(parsed.clip);
    this.action.play();
    this.frameTime = frameTime;
    Object.assign(this.state, {
      loaded: true, frames, fps: Math.round(1 / frameTime), frame: 0, name,
    });
    this.info.textContent = `${name}: ${frames} frames at ${this.state.fps} fps, `
      + `${parsed.skeleton.bones.length} bones`;
    this.setPlaceholder('');
    this.frame(parsed.clip.duration);
  }

  // Point the camera at the space the clip moves through (sampled over its duration).
  frame(duration) {
    const box = new THREE.Box3();
    const point = new THREE.Vector3();
    for (let i = 0; i <= 8; i += 1) {
      this.mixer.setTime((duration * i) / 8);
      this.root.updateMatrixWorld(true);
      this.root.traverse((bone) => box.expandByPoint(bone.getWorldPosition(point)));
    }
    this.mixer.setTime(0);
    const size = box.getSize(new THREE.Vector3());
    const centre = box.getCenter(new THREE.Vector3());
    const extent = Math.max(size.x, size.y, size.z, 1e-3);
    this.grid = new THREE.GridHelper(extent * 2, 20, 0x556070, 0x343a42);
    this.grid.position.set(centre.x, box.min.y, centre.z);
    this.scene.add(this.grid);
    this.camera.near = extent / 100;
    this.camera.far = extent * 100;
    this.camera.position.set(centre.x + extent * 0.6, centre.y + extent * 0.3, centre.z + extent * 1.6);
    this.camera.updateProjectionMatrix();
    if (this.controls) {
      this.controls.target.copy(centre);
      this.controls.update();
    } else {
      this.camera.lookAt(centre);
    }
  }

  tick(dt) {
    this.state.ticks += 1;
    if (this.mixer) {
      this.mixer.update(dt);
      const frame = Math.floor(this.action.time / this.frameTime + 1e-6);
      this.state.frame = Math.min(this.state.frames - 1, Math.max(0, frame));
    }
    if (this.renderer) {
      if (this.controls) this.controls.update();
      this.renderer.render(this.scene, this.camera);
    }
  }
}

const inputView = new SkeletonView($('input-view'), $('input-info'));
const resultView = new SkeletonView($('result-view'), $('result-info'));
state.input = inputView.state;
state.result = resultView.state;
inputView.setPlaceholder('Choose a BVH clip to see it here.');
resultView.setPlaceholder('Press Run to see the styled clip here.');

const clock = new THREE.Clock();
function animate() {
  const dt = Math.min(clock.getDelta(), 0.1);
  inputView.tick(dt);
  resultView.tick(dt);
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
  return parsed;
}

// ---------------------------------------------------------------------------------------------
// Styles

function styleNames() {
  const names = new Set();
  for (const family of ['translator', 'fast']) {
    for (const style of state.styles[family] || []) names.add(style.name);
  }
  return [...names].sort();
}

async function loadStyles() {
  const select = $('style-name');
  try {
    const response = await fetch('/v1/styles', { headers: { Accept: 'application/json' } });
    if (!response.ok) throw new Error(await describeFailure(response));
    state.styles = await response.json();
  } catch (error) {
    say(`Could not list the styles: ${error.message}`, 'error');
  }
  select.replaceChildren();
  let count = 0;
  for (const family of ['translator', 'fast']) {
    const styles = state.styles[family] || [];
    if (!styles.length) continue;
    const group = document.createElement('optgroup');
    group.label = family === 'translator' ? 'any clip (translator)' : 'fast networks';
    for (const style of styles) {
      const option = new Option(
        style.clips ? `${style.name} (${style.clips} clips)` : style.name, style.name,
      );
      option.dataset.family = family;
      group.appendChild(option);
      count += 1;
    }
    select.appendChild(group);
  }
  if (!count) select.appendChild(new Option('(no styles are served yet)', ''));
  const list = $('style-names');
  list.replaceChildren(...styleNames().map((name) => new Option(name, name)));
  const genre = $('genre');
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
    inputView.setPlaceholder('Choose a BVH clip to see it here.');
    return;
  }
  try {
    inputView.show(parseBvh(await file.text()), file.name);
    say(`${file.name} loaded: pick a style and press Run.`);
  } catch (error) {
    inputView.clear();
    inputView.setPlaceholder('This file could not be read as BVH.');
    say(`Could not read ${file.name} as BVH: ${error.message}`, 'error');
  }
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
  if (!content) return 'Choose a content BVH clip first.';
  form.append('content', content);
  if (mode === 'name') {
    const option = $('style-name').selectedOptions[0];
    const name = option ? option.value : '';
    form.append('style_name', name);
    if (option && option.dataset.family === 'fast') return { url: '/v1/stylize', form };
    form.append('strength', strength);
    return { url: '/v1/transfer', form };
  }
  if (mode === 'bvh') {
    const style = $('style-file').files[0];
    if (!style) return 'Choose a style BVH clip first.';
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

function filenameOf(response) {
  const disposition = response.headers.get('content-disposition') || '';
  const match = /filename\*?=(?:UTF-8'')?"?([^";]+)"?/i.exec(disposition);
  return match ? decodeURIComponent(match[1]) : 'result.bvh';
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
    const response = await fetch(request.url, {
      method: 'POST',
      body: request.form,
      headers: { Accept: 'text/plain, application/problem+json' },
    });
    if (!response.ok) {
      say(`${request.url} failed: ${await describeFailure(response)}`, 'error');
      return;
    }
    const text = await response.text();
    const name = filenameOf(response);
    resultView.show(parseBvh(text), name);
    if (downloadUrl) URL.revokeObjectURL(downloadUrl);
    downloadUrl = URL.createObjectURL(new Blob([text], { type: 'text/plain' }));
    state.download = { name, text };  // what the download button saves (read by tests)
    const link = $('download');
    link.href = downloadUrl;
    link.download = name;
    link.hidden = false;
    const timing = response.headers.get('server-timing');
    say(`Done: ${response.headers.get('x-frames') || resultView.state.frames} frames`
      + (timing ? ` (${timing})` : ''));
  } catch (error) {
    say(`${request.url} failed: ${error.message}`, 'error');
  } finally {
    button.disabled = false;
  }
}

// ---------------------------------------------------------------------------------------------
// Wiring

$('content-file').addEventListener('change', showInput);
$('controls').addEventListener('submit', run);
$('mix-add').addEventListener('click', () => addMixRow());
$('strength').addEventListener('input', () => {
  $('strength-value').textContent = Number($('strength').value).toFixed(2);
});
for (const [id, mode] of [['style-name', 'name'], ['style-file', 'bvh'],
  ['keypoints-file', 'keypoints'], ['audio-file', 'music'], ['genre', 'music']]) {
  $(id).addEventListener('change', () => {
    document.querySelector(`input[name="mode"][value="${mode}"]`).checked = true;
  });
}
addMixRow();
addMixRow('', 0.5);
loadStyles();
if ($('content-file').files[0]) showInput(); // a file kept by the browser across reloads
