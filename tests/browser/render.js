// The swatch of a fibrefit GLB in three.js (GLTFLoader, MeshPhysicalMaterial as loaded): one
// DirectionalLight of intensity E, an orthographic camera, no tone mapping, linear output, into
// a float render target read back with readRenderTargetPixels. `window.fibrefitRender` renders
// a list of direction pairs and returns the mean RGB radiance of the pixels (all on the swatch).
//
// Variants patch three.js's shader chunks (onBeforeCompile) to the Khronos specification, one
// departure at a time, so each departure's size is measured by rendering, not by a model of it:
//   diffuse      the direct diffuse's Fresnel weight with the dielectric's F90 = specularFactor
//                (three.js: mix(specularFactor, 1, metallic); they differ for 0 < metallic < 1)
//   multiscatter no multiple-scattering compensation factor on the direct specular
//   fresnel      Schlick's (1 - V.H)^5 instead of Epic's exp2((-5.55473 V.H - 6.98316) V.H)
//   sheen_v      the Sample Viewer's V_Sheen (Charlie lambda) instead of V_Neubelt
//   sheen_e      the sheen albedo scaling from E(mu) of the Charlie sheen (the spec's LUT,
//                tabulated by the caller) instead of IBLSheenBRDF's fitted exponential
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const SIZE = 4;
const renderer = new THREE.WebGLRenderer({ antialias: false });
renderer.toneMapping = THREE.NoToneMapping;
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
const target = new THREE.WebGLRenderTarget(SIZE, SIZE, {
  type: THREE.FloatType,
  format: THREE.RGBAFormat,
  colorSpace: THREE.LinearSRGBColorSpace,
  depthBuffer: true,
});

function replaceOnce(text, from, to, what) {
  const at = text.indexOf(from);
  if (at < 0 || text.indexOf(from, at + 1) >= 0) {
    throw new Error(`three.js ${THREE.REVISION}: the ${what} patch does not apply: ${JSON.stringify(from)} not found exactly once`);
  }
  return text.replace(from, to);
}

// the patches, as text edits of three.js's chunks; each throws if three.js's text changed
function patchedChunk(variant, sheenE) {
  let pars = THREE.ShaderChunk.lights_physical_pars_fragment;
  const on = (k) => variant.includes(k);
  if (on('diffuse')) {
    // three.js weights the diffuse by 1 - F_Schlick(F0 s, specularF90, V.H) with specularF90 =
    // mix(s, 1, metallic); the spec's dielectric has F90 = s (equal at metallic 0 and 1)
    pars = replaceOnce(pars,
      'reflectedLight.directDiffuse += irradiance * diffuseBRDF * ( 1.0 - F );',
      `{
        float f90D = material.metalness < 1.0 ? ( material.specularF90 - material.metalness ) / ( 1.0 - material.metalness ) : 1.0;
        vec3 FD = F_Schlick( material.specularColor, f90D, dotVH );
        reflectedLight.directDiffuse += irradiance * diffuseBRDF * ( vec3( 1.0 ) - FD );
      }`, 'diffuse');
  }
  if (on('multiscatter')) {
    pars = replaceOnce(pars,
      'reflectedLight.directSpecular += irradiance * specularBRDF * material.multiScatteringCompensation;',
      'reflectedLight.directSpecular += irradiance * specularBRDF;',
      'multiscatter');
  }
  if (on('sheen_v')) {
    pars = replaceOnce(pars, 'vec3 BRDF_Sheen(', `
      float fibrefitSheenL( float x, float a ) {
        float t = ( 1.0 - a ) * ( 1.0 - a );
        float pa = mix( 21.5473, 25.3245, t ), pb = mix( 3.82987, 3.32435, t ), pc = mix( 0.19823, 0.16801, t );
        float pd = mix( -1.97760, -1.27393, t ), pe = mix( -4.32054, -4.85967, t );
        return pa / ( 1.0 + pb * pow( x, pc ) ) + pd * x + pe;
      }
      float fibrefitSheenLambda( float c, float a ) {
        return abs( c ) < 0.5 ? exp( fibrefitSheenL( c, a ) ) : exp( 2.0 * fibrefitSheenL( 0.5, a ) - fibrefitSheenL( 1.0 - c, a ) );
      }
      float fibrefitVSheen( float dotNV, float dotNL, float a ) {
        return saturate( 1.0 / ( ( 1.0 + fibrefitSheenLambda( dotNV, a ) + fibrefitSheenLambda( dotNL, a ) ) * ( 4.0 * dotNV * dotNL ) ) );
      }
      vec3 BRDF_Sheen(`, 'sheen_v (definitions)');
    pars = replaceOnce(pars, 'float V = V_Neubelt( dotNV, dotNL );',
      'float V = fibrefitVSheen( dotNV, dotNL, pow2( sheenRoughness ) );', 'sheen_v');
  }
  if (on('sheen_e')) {
    const table = Array.from(sheenE, (x) => x.toFixed(9)).join(', ');
    pars = replaceOnce(pars, 'void RE_Direct_Physical(', `
      const float FIBREFIT_SHEEN_E[${sheenE.length}] = float[${sheenE.length}]( ${table} );
      float fibrefitSheenE( float mu ) {
        float x = saturate( mu ) * ${sheenE.length - 1}.0;
        int k = min( int( floor( x ) ), ${sheenE.length - 2} );
        float f = x - float( k );
        return mix( FIBREFIT_SHEEN_E[ k ], FIBREFIT_SHEEN_E[ k + 1 ], f );
      }
      void RE_Direct_Physical(`, 'sheen_e (table)');
    pars = replaceOnce(pars,
      'float sheenAlbedoV = IBLSheenBRDF( geometryNormal, geometryViewDir, material.sheenRoughness );',
      'float sheenAlbedoV = fibrefitSheenE( saturate( dot( geometryNormal, geometryViewDir ) ) );',
      'sheen_e (view)');
    pars = replaceOnce(pars,
      'float sheenAlbedoL = IBLSheenBRDF( geometryNormal, directLight.direction, material.sheenRoughness );',
      'float sheenAlbedoL = fibrefitSheenE( dotNL );',
      'sheen_e (light)');
  }
  return pars;
}

// three.js's common chunk with Schlick's (1 - V.H)^5 instead of Epic's exp2 fit of it
function patchedCommon() {
  const from = 'float fresnel = exp2( ( - 5.55473 * dotVH - 6.98316 ) * dotVH );';
  const common = THREE.ShaderChunk.common;
  if (common.split(from).length !== 3) {
    throw new Error(`three.js ${THREE.REVISION}: the fresnel patch does not apply: ${JSON.stringify(from)} not found twice`);
  }
  return common.replaceAll(from, 'float fresnel = pow( 1.0 - dotVH, 5.0 );');
}

const cache = new Map();
async function load(url) {
  if (!cache.has(url)) {
    cache.set(url, await new GLTFLoader().loadAsync(url));
  }
  return cache.get(url);
}

function dir(thetaDeg, phiDeg) {
  const t = THREE.MathUtils.degToRad(thetaDeg), p = THREE.MathUtils.degToRad(phiDeg);
  return new THREE.Vector3(Math.sin(t) * Math.cos(p), Math.sin(t) * Math.sin(p), Math.cos(t));
}

// what GLTFLoader made of the material, for the record
function describe(m) {
  return {
    type: m.type, color: m.color.toArray(), metalness: m.metalness, roughness: m.roughness,
    anisotropy: m.anisotropy, anisotropyRotation: m.anisotropyRotation, ior: m.ior,
    specularIntensity: m.specularIntensity, specularColor: m.specularColor.toArray(),
    sheen: m.sheen, sheenColor: m.sheenColor.toArray(), sheenRoughness: m.sheenRoughness,
    maps: ['map', 'anisotropyMap', 'roughnessMap'].filter((k) => m[k]),
    tangents: false,
  };
}

// Render `scene` seen from each pair's view (orthographic, along v) after `setLight(l)`, into the
// float target; the mean RGB of the pixels and how many the scene covers, per pair.
function measure(scene, pairs, setLight) {
  const camera = new THREE.OrthographicCamera(-0.05, 0.05, 0.05, -0.05, 0.1, 100);
  const out = [];
  const px = new Float32Array(SIZE * SIZE * 4);
  for (const [ti, pi, to, po] of pairs) {
    const l = dir(ti, pi), v = dir(to, po);
    setLight(l, v);
    camera.position.copy(v).multiplyScalar(10);
    camera.up.set(0, 0, 1);
    if (Math.abs(v.z) > 0.99) camera.up.set(0, 1, 0);
    camera.lookAt(0, 0, 0);
    camera.updateMatrixWorld();
    renderer.setRenderTarget(target);
    renderer.setClearColor(0x000000, 0);
    renderer.clear();
    renderer.render(scene, camera);
    renderer.readRenderTargetPixels(target, 0, 0, SIZE, SIZE, px);
    const rgb = [0, 0, 0];
    let covered = 0;
    for (let i = 0; i < SIZE * SIZE; i++) {
      if (px[4 * i + 3] > 0) covered++;
      for (let c = 0; c < 3; c++) rgb[c] += px[4 * i + c] / (SIZE * SIZE);
    }
    out.push({ rgb, covered });
  }
  renderer.setRenderTarget(null);
  return out;
}

// docs/web.md's ShaderMaterial recipe: `fibrefit export --shader glsl-es` (its first three lines,
// #version and precisions, left out: three.js writes its own with glslVersion GLSL3) before a
// main that shades a flat swatch (n = z, the fibres at psiDeg from x) under a light of E from L.
window.fibrefitShaderRender = async function (lib, pairs, E, psiDeg) {
  const psi = THREE.MathUtils.degToRad(psiDeg);
  const material = new THREE.ShaderMaterial({
    glslVersion: THREE.GLSL3,
    uniforms: {
      L: { value: new THREE.Vector3() }, V: { value: new THREE.Vector3() },
      T: { value: new THREE.Vector3(Math.cos(psi), Math.sin(psi), 0) }, E: { value: E },
    },
    vertexShader: 'void main() { gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
    fragmentShader: lib.split('\n').slice(3).join('\n') + `
      uniform vec3 L; uniform vec3 V; uniform vec3 T; uniform float E;
      out vec4 colour;
      void main() {
        vec3 n = vec3(0.0, 0.0, 1.0);
        colour = vec4(fibrefit_brdf(L, V, n, T) * E * max(dot(n, L), 0.0), 1.0);
      }`,
  });
  const scene = new THREE.Scene();
  scene.add(new THREE.Mesh(new THREE.PlaneGeometry(1, 1), material));
  const values = measure(scene, pairs, (l, v) => {
    material.uniforms.L.value.copy(l);
    material.uniforms.V.value.copy(v);
  });
  return { revision: THREE.REVISION, values };
};

window.fibrefitRender = async function (url, pairs, E, variant, sheenE) {
  const gltf = await load(url);
  const scene = new THREE.Scene();
  const root = gltf.scene.clone(true);
  scene.add(root);
  let material = null, hasTangents = false;
  root.traverse((o) => {
    if (o.isMesh) {
      material = o.material.clone();
      o.material = material;
      hasTangents = !!o.geometry.attributes.tangent;
    }
  });
  const key = `${variant.join('+')}`;
  if (variant.length) {
    const chunk = patchedChunk(variant, sheenE);
    material.onBeforeCompile = (shader) => {
      shader.fragmentShader = replaceOnce(shader.fragmentShader,
        '#include <lights_physical_pars_fragment>', chunk, 'chunk');
      if (variant.includes('fresnel')) {
        shader.fragmentShader = replaceOnce(shader.fragmentShader,
          '#include <common>', patchedCommon(), 'common');
      }
    };
    material.customProgramCacheKey = () => key;
  }
  const light = new THREE.DirectionalLight(0xffffff, E);
  scene.add(light);
  const out = measure(scene, pairs, (l) => {
    light.position.copy(l);
    light.target.position.set(0, 0, 0);
    light.target.updateMatrixWorld();
  });
  const d = describe(material);
  d.tangents = hasTangents;
  return { revision: THREE.REVISION, material: d, values: out };
};
window.fibrefitReady = true;
