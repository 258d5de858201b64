// What baker view's page imports from three.js: bundled and minified by esbuild into
// baker/view_static/three.min.js (see README.md beside this file).
export {
  AmbientLight, Box3, Color, DataTexture, LinearToneMapping, MathUtils, NearestFilter,
  NoColorSpace, PerspectiveCamera, RGBAFormat, Scene, Sphere, SRGBColorSpace, Vector3, WebGLRenderer,
} from 'three';
export { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
