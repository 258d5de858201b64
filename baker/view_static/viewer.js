// baker view: the baked file in three.js, with its MOZ_lightmap (our plugin), emissive or
// occlusion carrier, orbit controls and toggles (lightmap on/off, lightmap only, texel checker,
// exposure). Served by `baker view` from 127.0.0.1 with everything it needs: nothing is fetched
// from the internet.
//
// The page shades as three.js does for any user of the file: with Linear tone mapping (exposure
// x value, clipped) and sRGB output it draws diffuse colour x lightmap / pi + emission, the
// picture `baker preview` renders. URL parameters (for tests/test_browser.py and scripts):
// exposure=F (a factor; default the preview's automatic exposure), size=WxH (canvas pixels),
// camera=ex,ey,ez,tx,ty,tz,ux,uy,uz,fovDegrees (eye, target, up), bare=1 (no toolbar).

import {
  AmbientLight, Box3, Color, DataTexture, LinearToneMapping, MathUtils, NearestFilter,
  PerspectiveCamera, RGBAFormat, Scene, Sphere, SRGBColorSpace, Vector3, WebGLRenderer,
} from './three.min.js';
import { GLTFLoader, OrbitControls } from './three.min.js';
import { MozLightmapPlugin } from './moz_lightmap.js';

const params = new URLSearchParams(location.search);
const canvas = document.getElementById('view');
const renderer = new WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.toneMapping = LinearToneMapping;
renderer.outputColorSpace = SRGBColorSpace;
const scene = new Scene();
scene.background = new Color().setRGB(0.02, 0.02, 0.025); // baker preview's background
const camera = new PerspectiveCamera(50, 1, 0.01, 1000);
const controls = new OrbitControls(camera, canvas);
if (params.get('bare')) document.body.classList.add('bare');

const state = { lightmap: true, only: false, checker: false, stops: 0, exposure: 1 };
const carried = []; // { material, original: {...}, checker: DataTexture }

function size() {
  const fixed = (params.get('size') || '').split('x').map(Number);
  return fixed.length === 2 && fixed[0] > 0 ? fixed : [innerWidth, innerHeight];
}

function resize() {
  const [w, h] = size();
  renderer.setSize(w, h, !params.get('size'));
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}

// A checker of the carrier texture's texels: nearest-sampled, on its UV set.
function checkerFor(texture) {
  const image = texture.image;
  const w = image.width, h = image.height;
  const data = new Uint8Array(w * h * 4);
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      const v = (x + y) & 1 ? 200 : 70;
      data.set([v, v, v, 255], (y * w + x) * 4);
    }
  }
  const checker = new DataTexture(data, w, h, RGBAFormat);
  checker.magFilter = checker.minFilter = NearestFilter;
  checker.channel = texture.channel;
  checker.needsUpdate = true;
  return checker;
}

// Which map of a material carries the bake, by the file's carrier.
function carrierSlot(material, carrier) {
  if (material.lightMap) return 'lightMap';
  if (carrier === 'emissive' && material.emissiveMap) return 'emissiveMap';
  if (carrier === 'occlusion' && material.aoMap) return 'aoMap';
  return null;
}

function collect(root, carrier) {
  const seen = new Set();
  root.traverse((object) => {
    if (!object.isMesh) return;
    for (const material of Array.isArray(object.material) ? object.material : [object.material]) {
      if (seen.has(material)) continue;
      seen.add(material);
      const slot = carrierSlot(material, carrier);
      if (!slot) continue;
      const keys = ['map', 'color', 'metalness', 'roughness', 'metalnessMap', 'transmission',
        'emissive', 'emissiveMap', 'lightMap', 'lightMapIntensity', 'aoMap'];
      const original = {};
      for (const key of keys) {
        const value = material[key];
        original[key] = value && value.isColor ? value.clone() : value;
      }
      carried.push({ material, slot, original, checker: checkerFor(material[slot]) });
    }
  });
}

function apply() {
  for (const { material, slot, original, checker } of carried) {
    for (const [key, value] of Object.entries(original)) {
      if (key in material) material[key] = value && value.isColor ? value.clone() : value;
    }
    const bake = state.checker ? checker : original[slot];
    material[slot] = state.lightmap ? bake : null;
    if (slot === 'lightMap' && state.checker) material.lightMapIntensity = Math.PI;
    if (slot === 'emissiveMap' && !state.lightmap) material.emissive = new Color(0, 0, 0);
    if (slot === 'emissiveMap' && state.checker) material.emissive = new Color(1, 1, 1);
    if (state.only && slot !== 'emissiveMap') { // the bake on white, diffuse surfaces
      material.map = null;
      material.color = new Color(1, 1, 1);
      material.metalness = 0;
      material.metalnessMap = null;
      material.emissive = new Color(0, 0, 0);
      material.emissiveMap = null;
      if ('transmission' in material) material.transmission = 0;
    }
    material.needsUpdate = true;
  }
  renderer.toneMappingExposure = state.exposure * 2 ** state.stops;
  document.getElementById('stops').textContent = `${state.stops >= 0 ? '+' : ''}${state.stops} EV`;
}

// The view `baker preview` takes without a glTF camera: the bounds' centre seen from
// (0.6, 0.55, 1.0), far enough that the bounding sphere fits a 50 degree field of view.
function defaultView(root) {
  const box = new Box3().setFromObject(root);
  const centre = box.getCenter(new Vector3());
  const radius = Math.max(box.getSize(new Vector3()).length() / 2, 1e-6);
  const back = new Vector3(0.6, 0.55, 1.0).normalize();
  const fov = 50;
  const distance = radius / Math.sin(MathUtils.degToRad(fov / 2)) * 1.02;
  camera.fov = fov;
  camera.position.copy(centre).addScaledVector(back, distance);
  camera.up.set(0, 1, 0);
  controls.target.copy(centre);
}

function fixedView(text) {
  const v = text.split(',').map(Number);
  camera.position.set(v[0], v[1], v[2]);
  camera.up.set(v[6], v[7], v[8]);
  camera.fov = v[9];
  controls.target.set(v[3], v[4], v[5]);
}

// Near and far planes that hold the whole scene from wherever the camera is.
function clipPlanes(root) {
  const sphere = new Box3().setFromObject(root).getBoundingSphere(new Sphere());
  const far = camera.position.distanceTo(sphere.center) + sphere.radius;
  camera.far = far * 2;
  camera.near = far / 10000;
  camera.updateProjectionMatrix();
}

async function main() {
  const info = await (await fetch('info.json')).json();
  document.getElementById('name').textContent = info.name;
  state.exposure = Number(params.get('exposure') || info.exposure || 1);
  if (info.carrier === 'occlusion') scene.add(new AmbientLight(0xffffff, 1)); // what AO darkens
  const loader = new GLTFLoader();
  loader.register((parser) => new MozLightmapPlugin(parser));
  const gltf = await loader.loadAsync(info.model);
  scene.add(gltf.scene);
  collect(gltf.scene, info.carrier);
  if (params.get('camera')) fixedView(params.get('camera')); else defaultView(gltf.scene);
  resize();
  controls.update();
  clipPlanes(gltf.scene);
  controls.addEventListener('change', () => clipPlanes(gltf.scene));
  for (const id of ['lightmap', 'only', 'checker']) {
    document.getElementById(id).addEventListener('change', (event) => {
      state[id] = event.target.checked;
      apply();
    });
  }
  document.getElementById('exposure').addEventListener('input', (event) => {
    state.stops = Number(event.target.value);
    apply();
  });
  apply();
  document.getElementById('status').textContent =
    `${info.carrier} carrier, ${carried.length} baked material(s); drag to orbit, wheel to zoom`;
  renderer.setAnimationLoop(() => { controls.update(); renderer.render(scene, camera); });
  renderer.render(scene, camera);
  window.bakerViewReady = true;
}

addEventListener('resize', resize);
main().catch((error) => {
  document.getElementById('status').textContent = `error: ${error.message}`;
  window.bakerViewError = String(error);
});
