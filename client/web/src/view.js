// The 3D view: the mesh, the field glyphs, the constraints and the singularities, with orbit and
// zoom (OrbitControls) and picking (a raycaster on the mesh).
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { acceleratedRaycast, computeBoundsTree, disposeBoundsTree } from "three-mesh-bvh";

// Picking walks a bounding volume hierarchy instead of every triangle (a 1M-face mesh: ~1 s to
// build once, then well under a millisecond per ray).
THREE.BufferGeometry.prototype.computeBoundsTree = computeBoundsTree;
THREE.BufferGeometry.prototype.disposeBoundsTree = disposeBoundsTree;
THREE.Mesh.prototype.raycast = acceleratedRaycast;

/**
 * Whether WebGL runs in software (SwiftShader, llvmpipe): there multisampling multiplies the
 * CPU cost of every frame by the sample count, and that CPU is the one the page's design round
 * trips need (docs/studio.md, Performance).
 */
function softwareGL() {
  const gl = document.createElement("canvas").getContext("webgl2");
  if (!gl) return false;
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  const renderer = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  gl.getExtension("WEBGL_lose_context")?.loseContext();
  return /swiftshader|llvmpipe|softpipe|software/i.test(renderer);
}

const SOFTWARE_FRAMES_PER_SECOND = 10;

export class View {
  constructor(container) {
    this.container = container;
    this.software = softwareGL();
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software,
      preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    this.renderer.setClearColor(0xf4f4f2);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1000);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x707070, 2.2));
    const light = new THREE.DirectionalLight(0xffffff, 1.2);
    light.position.set(1, 2, 3);
    this.camera.add(light);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.mouseButtons = { LEFT: THREE.MOUSE.ROTATE, MIDDLE: THREE.MOUSE.PAN,
      RIGHT: THREE.MOUSE.ROTATE };
    this.controls.addEventListener("change", () => this.requestRender());
    this.raycaster = new THREE.Raycaster();
    this.raycaster.firstHitOnly = true;  // three-mesh-bvh: the nearest hit only
    this.mesh = null;
    this.glyphs = null;
    // What is drawn over the mesh: glyphs, markers, strokes, singularities (flat colours).
    this.overlay = new THREE.Group();
    this.scene.add(this.overlay);
    this.markers = new THREE.Group();
    this.overlay.add(this.markers);
    this.strokes = new THREE.Group();
    this.overlay.add(this.strokes);
    this.meshImage = null;  // the last drawn mesh's colours (see draw)
    this.meshKey = null;    // the camera and size it was drawn with
    this.backdrop = backdrop();
    this.singularities = null;
    this.labels = document.createElement("div");
    this.labels.className = "labels";
    container.appendChild(this.labels);
    this.singularityList = [];
    this.frameTimes = [];
    this.renderPending = false;
    this.lastFrame = -Infinity;
    this.beforeFrameCallbacks = [];
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.container;
    if (w === 0 || h === 0) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  /** Shows a mesh (positions: 3 per vertex, faces: 3 per face) and frames the camera on it. */
  setMesh(positions, faces) {
    if (this.mesh) {
      this.scene.remove(this.mesh);
      this.mesh.geometry.disposeBoundsTree();
      this.mesh.geometry.dispose();
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(Float32Array.from(positions), 3));
    geometry.setIndex(new THREE.BufferAttribute(Uint32Array.from(faces), 1));
    geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
    geometry.computeBoundsTree({ indirect: true });  // keeps the index: faceIndex = face id
    this.mesh = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({
      color: 0xb9b9b9, flatShading: true,
      side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1,
      polygonOffsetUnits: 1 }));
    this.scene.add(this.mesh);
    const { center, radius } = geometry.boundingSphere;
    this.radius = radius;
    this.controls.target.copy(center);
    this.camera.near = radius / 100;
    this.camera.far = radius * 100;
    this.camera.position.copy(center).add(new THREE.Vector3(0.35, 0.5, 1).normalize()
      .multiplyScalar(radius * 2.9));
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  /** Replaces the glyphs: line segments with per-vertex colours (glyphs.js, fieldGlyphs). */
  setGlyphs(positions, colors) {
    if (!this.glyphs) {
      this.glyphs = new THREE.LineSegments(new THREE.BufferGeometry(),
        new THREE.LineBasicMaterial({ vertexColors: true }));
      this.glyphs.frustumCulled = false;
      this.overlay.add(this.glyphs);
    }
    const g = this.glyphs.geometry;
    g.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    g.setAttribute("color", new THREE.BufferAttribute(colors, 3));
    g.computeBoundingSphere();
    this.requestRender();
  }

  setGlyphsVisible(on) {
    if (this.glyphs) this.glyphs.visible = on;
    this.draw();
  }

  /** Constraint markers: [{ id, position, direction (unit, ambient), hard, selected }]; a marker
   *  without direction (a placed singularity) is a diamond. */
  setMarkers(markers, size) {
    for (const child of [...this.markers.children]) {
      this.markers.remove(child);
      child.geometry?.dispose();
    }
    for (const m of markers) {
      const color = markerColor(m);
      const dot = new THREE.Mesh(m.direction ? new THREE.SphereGeometry(0.3 * size, 12, 8)
        : new THREE.OctahedronGeometry(0.45 * size), new THREE.MeshBasicMaterial({ color }));
      dot.position.set(...m.position);
      this.markers.add(dot);
      if (!m.direction) continue;
      const arrow = new THREE.ArrowHelper(new THREE.Vector3(...m.direction),
        new THREE.Vector3(...m.position), 2 * size, color, 0.6 * size, 0.35 * size);
      this.markers.add(arrow);
    }
    this.requestRender();
  }

  /** Strokes: [{ points: [[x, y, z], ...], hard, selected }], drawn as tubes of radius `size`
   *  in the markers' colours; `preview`: the points of a stroke being drawn (a line), or null. */
  setStrokes(strokes, size, preview = null) {
    for (const child of [...this.strokes.children]) {
      this.strokes.remove(child);
      child.geometry.dispose();
    }
    for (const stroke of strokes) {
      const path = new THREE.CurvePath();
      for (let i = 1; i < stroke.points.length; i++) {
        path.add(new THREE.LineCurve3(new THREE.Vector3(...stroke.points[i - 1]),
          new THREE.Vector3(...stroke.points[i])));
      }
      this.strokes.add(new THREE.Mesh(
        new THREE.TubeGeometry(path, 4 * stroke.points.length, size, 6),
        new THREE.MeshBasicMaterial({ color: markerColor(stroke) })));
    }
    if (preview && preview.length > 1) {
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(
        preview.map((p) => new THREE.Vector3(...p))), new THREE.LineBasicMaterial({
        color: 0x6a1b9a, depthTest: false }));
      line.frustumCulled = false;
      this.strokes.add(line);
    }
    this.requestRender();
  }

  /** Singular vertices: [{ vertex, position, index, n }]; round dots lifted off the surface
   *  along the vertex normal (so the surface does not cut them) and their index as labels. */
  setSingularities(list, lift = 0) {
    const normals = this.mesh?.geometry.getAttribute("normal");
    list = list.map((s) => (normals && lift > 0 ? { ...s, position: [0, 1, 2].map((k) =>
      s.position[k] + lift * normals.array[3 * s.vertex + k]) } : s));
    this.singularityList = list;
    if (this.singularities) {
      this.overlay.remove(this.singularities);
      this.singularities.geometry.dispose();
    }
    const positions = new Float32Array(list.flatMap((s) => s.position));
    const colors = new Float32Array(list.flatMap((s) => (s.index > 0 ? [0.85, 0.1, 0.1]
      : [0.1, 0.3, 0.9])));
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3));
    this.dotTexture ??= roundDot();
    this.singularities = new THREE.Points(geometry, new THREE.PointsMaterial({
      size: 12, sizeAttenuation: false, vertexColors: true, map: this.dotTexture,
      alphaTest: 0.5, transparent: true }));
    this.overlay.add(this.singularities);
    this.labels.replaceChildren(...list.map((s) => {
      const label = document.createElement("span");
      label.textContent = s.n === 1 ? String(s.index) : `${s.index}/${s.n}`;
      return label;
    }));
    this.requestRender();
  }

  /** The face under a canvas point (CSS pixels from the canvas's top left) and the point hit,
   *  or null. */
  pick(x, y) {
    if (!this.mesh) return null;
    this.raycaster.setFromCamera(this.ndc(x, y), this.camera);
    const hit = this.raycaster.intersectObject(this.mesh, false)[0];
    return hit ? { face: hit.faceIndex, point: hit.point.toArray() } : null;
  }

  /** Where the ray through a canvas point meets the plane through `point` with `normal`. */
  planePoint(x, y, point, normal) {
    this.raycaster.setFromCamera(this.ndc(x, y), this.camera);
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(
      new THREE.Vector3(...normal), new THREE.Vector3(...point));
    const hit = this.raycaster.ray.intersectPlane(plane, new THREE.Vector3());
    return hit ? hit.toArray() : null;
  }

  /** The ambient length of one CSS pixel at the distance of the orbit's target. */
  pixelSize() {
    const distance = this.camera.position.distanceTo(this.controls.target);
    const height = this.renderer.domElement.clientHeight || 1;
    return (2 * distance * Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2)) / height;
  }

  /** A test (x, y, z) -> whether the point is inside the camera's view frustum. */
  inView() {
    this.camera.updateMatrixWorld();
    const frustum = new THREE.Frustum().setFromProjectionMatrix(new THREE.Matrix4()
      .multiplyMatrices(this.camera.projectionMatrix, this.camera.matrixWorldInverse));
    const p = new THREE.Vector3();
    return (x, y, z) => frustum.containsPoint(p.set(x, y, z));
  }

  /** Canvas CSS pixel position of an ambient point. */
  screenOf(point) {
    const v = new THREE.Vector3(...point).project(this.camera);
    const { clientWidth: w, clientHeight: h } = this.renderer.domElement;
    return [(v.x + 1) / 2 * w, (1 - v.y) / 2 * h];
  }

  ndc(x, y) {
    const { clientWidth: w, clientHeight: h } = this.renderer.domElement;
    return new THREE.Vector2((x / w) * 2 - 1, -(y / h) * 2 + 1);
  }

  /** Runs `callback` at the start of the next frame (before it draws), and asks for a frame. */
  beforeFrame(callback) {
    this.beforeFrameCallbacks.push(callback);
    this.requestRender();
  }

  requestRender() {
    if (this.renderPending) return;
    this.renderPending = true;
    const frame = () => requestAnimationFrame(() => {
      const start = performance.now();
      // What they change is drawn by this frame (their requestRender()s find it pending).
      for (const callback of this.beforeFrameCallbacks.splice(0)) callback();
      this.renderPending = false;
      this.draw();
      this.placeLabels();
      this.lastFrame = performance.now();
      this.frameTimes.push(this.lastFrame - start);
      if (this.frameTimes.length > 100) this.frameTimes.shift();
      if (this.beforeFrameCallbacks.length) this.requestRender();
    });
    // Software GL draws on the CPU that the design round trips need: at most
    // SOFTWARE_FRAMES_PER_SECOND frames there, the rest of the time left to them.
    const wait = this.software ? this.lastFrame + 1000 / SOFTWARE_FRAMES_PER_SECOND -
      performance.now() : 0;
    if (wait > 0) {
      setTimeout(frame, wait);
    } else {
      frame();
    }
  }

  // Labels follow their dots on screen; a label whose dot the mesh hides is hidden too.
  placeLabels() {
    const labels = this.labels.children;
    const eye = this.camera.position;
    const ray = new THREE.Raycaster();
    ray.firstHitOnly = true;
    this.singularityList.forEach((s, i) => {
      const point = new THREE.Vector3(...s.position);
      const distance = point.distanceTo(eye);
      ray.set(eye, point.clone().sub(eye).normalize());
      ray.far = distance;
      const hidden = this.mesh !== null &&
        ray.intersectObject(this.mesh, false).some((hit) => hit.distance < distance * 0.999);
      const [x, y] = this.screenOf(s.position);
      labels[i].style.visibility = hidden ? "hidden" : "visible";
      labels[i].style.transform = `translate(${x + 6}px, ${y - 18}px)`;
    });
  }

  /** The camera as the tests need it to cast rays themselves (column-major matrices). */
  cameraState() {
    this.camera.updateMatrixWorld();
    const { clientWidth: width, clientHeight: height } = this.renderer.domElement;
    return { position: this.camera.position.toArray(),
      projectionMatrixInverse: this.camera.projectionMatrixInverse.toArray(),
      matrixWorld: this.camera.matrixWorld.toArray(), width, height };
  }

  /**
   * Draws the view now. The mesh is drawn only when the camera, the size or the mesh changed: a
   * large mesh takes seconds per frame under software GL or a slow GPU, while a design edit
   * changes only what lies over it. The mesh's colours are then copied to a texture and its depth
   * stays in the drawing buffer (preserveDrawingBuffer); the overlay is drawn without writing
   * depth. Otherwise the copy is drawn back (depth untouched) and the overlay over it.
   */
  draw() {
    const r = this.renderer;
    if (this.mesh === null) {
      r.render(this.scene, this.camera);
      return;
    }
    const size = r.getDrawingBufferSize(new THREE.Vector2());
    this.camera.updateMatrixWorld();
    const key = [...this.camera.matrixWorld.elements, ...this.camera.projectionMatrix.elements,
      size.x, size.y, this.mesh.id].join();
    if (key !== this.meshKey) {
      this.overlay.visible = false;
      r.render(this.scene, this.camera);
      this.overlay.visible = true;
      if (this.meshImage?.image.width !== size.x || this.meshImage?.image.height !== size.y) {
        this.meshImage?.dispose();
        this.meshImage = new THREE.FramebufferTexture(size.x, size.y);
        this.backdrop.material.uniforms.image.value = this.meshImage;
      }
      r.copyFramebufferToTexture(this.meshImage);
      this.meshKey = key;
    } else {
      this.drawOver(this.backdrop.scene, this.backdrop.camera);
    }
    this.mesh.visible = false;
    this.drawOver(this.scene, this.camera);
    this.mesh.visible = true;
  }

  // Renders a scene over what the drawing buffer holds: no clear, no depth written.
  drawOver(scene, camera) {
    const r = this.renderer;
    const depth = r.state.buffers.depth;
    r.autoClear = false;
    depth.setMask(false);
    depth.setLocked(true);
    r.render(scene, camera);
    depth.setLocked(false);
    depth.setMask(true);  // else the next clear would leave the depth as it is
    r.autoClear = true;
  }

  /** A PNG of the view. */
  png() {
    this.draw();
    return new Promise((resolve) => this.renderer.domElement.toBlob(resolve, "image/png"));
  }
}

// A full-view quad showing a texture's texels as they are (the mesh's image, see View.draw).
function backdrop() {
  const material = new THREE.ShaderMaterial({
    uniforms: { image: { value: null } },
    vertexShader: "varying vec2 uv_;\nvoid main() { uv_ = uv; gl_Position = vec4(position.xy, 0.0, 1.0); }",
    fragmentShader: "uniform sampler2D image;\nvarying vec2 uv_;\n" +
      "void main() { gl_FragColor = texture2D(image, uv_); }",
    depthTest: false, depthWrite: false });
  const scene = new THREE.Scene();
  const quad = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), material);
  quad.frustumCulled = false;
  scene.add(quad);
  return { scene, camera: new THREE.OrthographicCamera(), material };
}

function markerColor(m) {
  return m.selected ? 0x1565c0 : m.hard ? 0xc62828 : 0xef6c00;
}

// A white disc on transparent ground: the shape of a point sprite.
function roundDot() {
  const canvas = document.createElement("canvas");
  canvas.width = canvas.height = 64;
  const g = canvas.getContext("2d");
  g.fillStyle = "#fff";
  g.beginPath();
  g.arc(32, 32, 30, 0, 2 * Math.PI);
  g.fill();
  return new THREE.CanvasTexture(canvas);
}
