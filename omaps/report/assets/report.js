// omaps report: the page's behaviour. Sortable tables, the per-material scheme pictures, and the
// 3D view (three.js, the global THREE) of the scene's meshes with each alpha triangle's map states.
// The data is the JSON of <script id="omaps-data">; window.omapsReport is the page's handle
// (ready, setScheme, setMode, schemes), which the browser tests use.
"use strict";

(function () {
  const data = JSON.parse(document.getElementById("omaps-data").textContent);
  const api = { ready: false, frames: 0, errors: [], schemes: [], scheme: null, mode: "states" };
  window.omapsReport = api;

  // ---- sortable tables: click a header; numbers sort by data-v -------------------------------
  document.querySelectorAll("table.sortable").forEach((table) => {
    table.querySelectorAll("th").forEach((th, col) => {
      th.addEventListener("click", () => {
        const body = table.tBodies[0];
        const rows = Array.from(body.rows);
        const dir = th.dataset.dir === "asc" ? -1 : 1;
        table.querySelectorAll("th").forEach((h) => delete h.dataset.dir);
        th.dataset.dir = dir === 1 ? "asc" : "desc";
        const key = (r) => {
          const c = r.cells[col];
          const v = c.dataset.v;
          return v !== undefined ? parseFloat(v) : c.textContent.trim().toLowerCase();
        };
        rows.sort((a, b) => {
          const x = key(a), y = key(b);
          return (x < y ? -1 : x > y ? 1 : 0) * dir;
        });
        rows.forEach((r) => body.appendChild(r));
      });
    });
  });

  // ---- per-material pictures follow the scheme selector --------------------------------------
  function showMaterialScheme(name) {
    document.querySelectorAll("img[data-scheme-images]").forEach((img) => {
      const srcs = JSON.parse(img.dataset.schemeImages);
      if (srcs[name]) img.src = srcs[name];
    });
  }

  const view = data.view;
  if (!view) {
    api.ready = true;
    return;
  }

  // ---- decoding ------------------------------------------------------------------------------
  function bytes(b64) {
    const s = atob(b64);
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }
  const f32 = (b64) => new Float32Array(bytes(b64).buffer);
  const u32 = (b64) => new Uint32Array(bytes(b64).buffer);
  function imageTexture(uri, nearest, repeat) {
    const img = new Image();
    const tex = new THREE.Texture(img);
    tex.flipY = false;
    tex.generateMipmaps = !nearest;
    tex.minFilter = nearest ? THREE.NearestFilter : THREE.LinearFilter;
    tex.magFilter = nearest ? THREE.NearestFilter : THREE.LinearFilter;
    tex.wrapS = tex.wrapT = repeat ? THREE.RepeatWrapping : THREE.ClampToEdgeWrapping;
    tex.colorSpace = THREE.NoColorSpace;
    const loaded = new Promise((resolve, reject) => {
      img.onload = () => { tex.needsUpdate = true; resolve(tex); };
      img.onerror = () => reject(new Error("an embedded image did not decode"));
    });
    img.src = uri;
    return { tex, loaded };
  }

  // ---- the scene -----------------------------------------------------------------------------
  const canvas = document.getElementById("view3d");
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x20242b);
  const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 1000);
  const controls = new THREE.OrbitControls(camera, canvas);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 1.5);
  sun.position.set(0.4, 1, 0.3);
  scene.add(sun);

  const vertexShader = `
    in float slot;
    in vec2 auv;
    out vec2 vBary;
    out vec2 vUv;
    out vec3 vView;
    flat out int vSlot;
    void main() {
      int c = gl_VertexID % 3;
      vBary = c == 1 ? vec2(1.0, 0.0) : (c == 2 ? vec2(0.0, 1.0) : vec2(0.0));
      vUv = auv;
      vSlot = int(slot + 0.5);
      vec4 p = vec4(position, 1.0);
      #ifdef USE_INSTANCING
        p = instanceMatrix * p;
      #endif
      vec4 mv = modelViewMatrix * p;
      vView = mv.xyz;
      gl_Position = projectionMatrix * mv;
    }`;
  const fragmentShader = `
    precision highp float;
    precision highp int;
    uniform sampler2D atlas;
    uniform sampler2D alphaTex;
    uniform int mode;
    uniform int res;
    uniform int cols;
    uniform float threshold;
    in vec2 vBary;
    in vec2 vUv;
    in vec3 vView;
    flat in int vSlot;
    out vec4 fragColour;
    void main() {
      vec3 n = normalize(cross(dFdx(vView), dFdy(vView)));
      float shade = 0.8 + 0.2 * abs(n.z);
      vec3 c;
      if (mode == 0) {
        int i = clamp(int(floor(vBary.x * float(res))), 0, res - 1);
        int j = clamp(int(floor(vBary.y * float(res))), 0, res - 1 - i);
        int tile = vSlot / 2;
        int ox = (tile % cols) * res;
        int oy = (tile / cols) * (res + 1);
        ivec2 p = (vSlot % 2 == 0) ? ivec2(ox + i, oy + j) : ivec2(ox + res - 1 - i, oy + res - j);
        c = texelFetch(atlas, p, 0).rgb;
      } else {
        vec4 t = texture(alphaTex, vUv);
        if (mode == 1) {
          c = vec3(t.a);
        } else {
          if (t.a < threshold) discard;
          c = t.rgb;
          shade = 0.45 + 0.55 * abs(n.z);
        }
      }
      fragColour = vec4(c * shade, 1.0);
    }`;

  const box = new THREE.Box3(new THREE.Vector3(...view.bounds[0]), new THREE.Vector3(...view.bounds[1]));
  const pending = [];
  const alphaMaterials = {}; // material index -> ShaderMaterial
  for (const [m, mat] of Object.entries(view.materials)) {
    const t = imageTexture(mat.texture, false, true);
    pending.push(t.loaded);
    alphaMaterials[m] = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3, vertexShader, fragmentShader, side: THREE.DoubleSide,
      uniforms: { atlas: { value: null }, alphaTex: { value: t.tex }, mode: { value: 0 }, res: { value: 1 },
                  cols: { value: 1 }, threshold: { value: mat.threshold } },
    });
  }
  const alphaGeometries = [];
  for (const proto of view.protos) {
    const matrices = f32(proto.instances);
    const place = (mesh) => {
      const m4 = new THREE.Matrix4();
      for (let i = 0; i < proto.instance_count; i++) {
        m4.fromArray(matrices, 16 * i);
        mesh.setMatrixAt(i, m4);
      }
      mesh.instanceMatrix.needsUpdate = true;
      mesh.computeBoundingSphere();
      scene.add(mesh);
    };
    if (proto.opaque.groups.length) {
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(f32(proto.opaque.pos), 3));
      const mats = proto.opaque.groups.map(([start, count, colour], i) => {
        g.addGroup(start, count, i);
        return new THREE.MeshLambertMaterial({ color: new THREE.Color(...colour), flatShading: true,
                                               side: THREE.DoubleSide });
      });
      g.computeVertexNormals();
      place(new THREE.InstancedMesh(g, mats, proto.instance_count));
    }
    if (proto.alpha.count) {
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(f32(proto.alpha.pos), 3));
      g.setAttribute("auv", new THREE.BufferAttribute(f32(proto.alpha.uv), 2));
      g.setAttribute("slot", new THREE.BufferAttribute(new Float32Array(3 * proto.alpha.count), 1));
      const mats = proto.alpha.groups.map(([start, count, m], i) => {
        g.addGroup(start, count, i);
        return alphaMaterials[m];
      });
      alphaGeometries.push({ g, start: proto.alpha.start, count: proto.alpha.count });
      place(new THREE.InstancedMesh(g, mats, proto.instance_count));
    }
  }

  // ---- schemes and modes ---------------------------------------------------------------------
  const schemes = {};
  for (const s of view.schemes) {
    const t = imageTexture(s.atlas, true, false);
    pending.push(t.loaded);
    schemes[s.name] = { ...s, tex: t.tex, slotArray: null };
    api.schemes.push(s.name);
  }
  let needsRender = true;
  function setScheme(name) {
    const s = schemes[name];
    if (!s) throw new Error("no scheme " + name);
    if (!s.slotArray) s.slotArray = u32(s.slots);
    for (const { g, start, count } of alphaGeometries) {
      const attr = g.getAttribute("slot");
      for (let t = 0; t < count; t++) {
        const v = s.slotArray[start + t];
        attr.array[3 * t] = attr.array[3 * t + 1] = attr.array[3 * t + 2] = v;
      }
      attr.needsUpdate = true;
    }
    for (const m of Object.values(alphaMaterials)) {
      m.uniforms.atlas.value = s.tex;
      m.uniforms.res.value = s.res;
      m.uniforms.cols.value = s.cols;
    }
    api.scheme = name;
    document.getElementById("scheme-select").value = name;
    const info = document.getElementById("scheme-info");
    if (info) info.textContent = `${s.distinct} distinct triangle images, ${s.res} texels per leg; ` +
      `${(100 * s.known).toFixed(1)} % of the drawn area known (T or O)`;
    showMaterialScheme(name);
    draw();
  }
  const MODES = { states: 0, alpha: 1, texture: 2 };
  function setMode(mode) {
    if (!(mode in MODES)) throw new Error("no mode " + mode);
    for (const m of Object.values(alphaMaterials)) m.uniforms.mode.value = MODES[mode];
    api.mode = mode;
    document.querySelectorAll("input[name=mode]").forEach((r) => { r.checked = r.value === mode; });
    draw();
  }
  api.setScheme = setScheme;
  api.setMode = setMode;
  api.renderedFrames = () => api.frames;
  const select = document.getElementById("scheme-select");
  select.addEventListener("change", () => setScheme(select.value));
  document.querySelectorAll("input[name=mode]").forEach((r) => r.addEventListener("change", () => setMode(r.value)));

  // ---- the camera ----------------------------------------------------------------------------
  const size = box.getSize(new THREE.Vector3()).length() || 1;
  camera.near = size / 2000;
  camera.far = size * 20;
  if (view.camera) {
    camera.position.set(...view.camera.eye);
    controls.target.set(...view.camera.target);
    camera.fov = view.camera.fov;
    if (view.camera.up) camera.up.set(...view.camera.up);
  } else {
    const c = box.getCenter(new THREE.Vector3());
    controls.target.copy(c);
    camera.position.set(c.x + 0.6 * size, c.y + 0.3 * size, c.z + 0.6 * size);
  }
  camera.updateProjectionMatrix();
  controls.update();
  controls.addEventListener("change", () => { needsRender = true; });
  document.getElementById("reset-view").addEventListener("click", () => { controls.reset(); needsRender = true; });
  controls.saveState();

  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== w || canvas.height !== h) {
      renderer.setSize(w, h, false);
      camera.aspect = w / Math.max(1, h);
      camera.updateProjectionMatrix();
      needsRender = true;
    }
  }
  function draw() {  // at once (a scheme or mode chosen), not at the next animation frame
    resize();
    renderer.render(scene, camera);
    needsRender = false;
    api.frames++;
    if (loaded) api.ready = true;
  }
  function frame() {
    resize();
    if (needsRender) draw();
    requestAnimationFrame(frame);
  }
  let loaded = false;
  Promise.all(pending).then(() => {
    loaded = true;
    setScheme(view.initial || api.schemes[0]);
    setMode("states");
    requestAnimationFrame(frame);
  }).catch((e) => { api.errors.push(String(e)); console.error(e); });
})();
