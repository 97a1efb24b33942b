// What the viewer draws with three.js: the tissue's surface (the session's surface
// triangles over the frame's surface positions) shaded by a display field, the tool,
// the contact force on it as an arrow, and the contact patch (the particles in contact).
// A body without a surface (a node-list cloud) is drawn as points.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import type { FrameData, SessionInfo } from "./session";

// A perceptually ordered colour map (viridis, five stops, linear in between).
const STOPS: [number, number, number][] = [
  [0.267, 0.005, 0.329],
  [0.229, 0.322, 0.546],
  [0.128, 0.567, 0.551],
  [0.369, 0.789, 0.383],
  [0.993, 0.906, 0.144],
];
export function colour(t: number, out: Float32Array, at: number): void {
  const s = Math.min(Math.max(t, 0), 1) * (STOPS.length - 1);
  const i = Math.min(Math.floor(s), STOPS.length - 2);
  const f = s - i;
  for (let c = 0; c < 3; c++) out[at + c] = STOPS[i][c] + f * (STOPS[i + 1][c] - STOPS[i][c]);
}
export const COLOUR_BAR_CSS = `linear-gradient(to right, ${STOPS.map((s) => `rgb(${s.map((c) => Math.round(255 * c)).join(",")})`).join(", ")})`;

export class TissueView {
  readonly renderer: THREE.WebGLRenderer;
  readonly camera: THREE.PerspectiveCamera;
  readonly controls: OrbitControls;
  private scene = new THREE.Scene();
  private body: THREE.Mesh | THREE.Points;
  private geometry = new THREE.BufferGeometry();
  private positions: Float32Array;
  private colours: Float32Array;
  private tool: THREE.Mesh;
  private arrow: THREE.ArrowHelper;
  private patch: THREE.Points;
  private patchPositions: Float32Array;
  private localIndex: Int32Array; // particle -> index in the frame's lists (-1: not sent)
  private surface: boolean;
  private dirty = true;
  fieldRange = 0; // the colour bar's top (field units); 0 = not set yet
  forceScale = 0; // N drawn as one tool radius of arrow

  constructor(
    readonly canvas: HTMLCanvasElement,
    readonly info: SessionInfo,
  ) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.scene.background = new THREE.Color(0x1b1e24);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 1.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.5);
    sun.position.set(1, -2, 3);
    this.scene.add(sun);

    const n = info.particleCount;
    this.surface = info.surfaceVertices.length > 0 && info.surfaceTriangles.length > 0;
    const sent = this.surface ? info.surfaceVertices : null;
    const count = sent ? sent.length : n;
    this.localIndex = new Int32Array(n).fill(-1);
    for (let k = 0; k < count; k++) this.localIndex[sent ? sent[k] : k] = k;
    this.positions = new Float32Array(3 * count);
    for (let k = 0; k < count; k++) {
      const p = sent ? sent[k] : k;
      for (let c = 0; c < 3; c++) this.positions[3 * k + c] = info.restPositions[3 * p + c];
    }
    this.colours = new Float32Array(3 * count);
    for (let k = 0; k < count; k++) colour(0, this.colours, 3 * k);
    this.geometry.setAttribute("position", new THREE.BufferAttribute(this.positions, 3).setUsage(THREE.DynamicDrawUsage));
    this.geometry.setAttribute("color", new THREE.BufferAttribute(this.colours, 3).setUsage(THREE.DynamicDrawUsage));
    if (this.surface) {
      const index = new Uint32Array(info.surfaceTriangles.length);
      for (let k = 0; k < index.length; k++) index[k] = this.localIndex[info.surfaceTriangles[k]];
      this.geometry.setIndex(new THREE.BufferAttribute(index, 1));
      this.geometry.computeVertexNormals();
      this.body = new THREE.Mesh(
        this.geometry,
        new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.7, metalness: 0.0, side: THREE.DoubleSide }),
      );
    } else {
      this.body = new THREE.Points(this.geometry, new THREE.PointsMaterial({ vertexColors: true, size: 3, sizeAttenuation: false }));
    }
    this.scene.add(this.body);

    const r = info.radius;
    this.tool = new THREE.Mesh(
      new THREE.SphereGeometry(r, 48, 24),
      new THREE.MeshStandardMaterial({ color: 0xd8d8e0, roughness: 0.35, metalness: 0.1, transparent: true, opacity: 0.4, depthWrite: false }),
    );
    this.scene.add(this.tool);
    this.arrow = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), r, 0xff5533, 0.35 * r, 0.2 * r);
    this.arrow.visible = false;
    this.scene.add(this.arrow);
    this.patchPositions = new Float32Array(3 * 4096);
    const patchGeometry = new THREE.BufferGeometry();
    patchGeometry.setAttribute("position", new THREE.BufferAttribute(this.patchPositions, 3).setUsage(THREE.DynamicDrawUsage));
    patchGeometry.setDrawRange(0, 0);
    this.patch = new THREE.Points(patchGeometry, new THREE.PointsMaterial({ color: 0xff3355, size: 6, sizeAttenuation: false, depthTest: false }));
    this.patch.renderOrder = 2;
    this.scene.add(this.patch);

    // The camera looks at the touch point from above and aside, far enough for the body.
    const box = new THREE.Box3().setFromBufferAttribute(new THREE.BufferAttribute(info.restPositions, 3));
    const size = box.getSize(new THREE.Vector3()).length();
    const centre = box.getCenter(new THREE.Vector3());
    this.camera = new THREE.PerspectiveCamera(40, 1, size / 1000, size * 20);
    this.camera.up.set(0, 0, 1);
    // Close enough to see the dimple (five tool radii), never closer than a third of the body.
    const look = new THREE.Vector3(centre.x, centre.y, info.touchHeight - info.radius);
    const distance = Math.min(Math.max(5 * info.radius, 0.3 * size), size);
    const from = new THREE.Vector3(0.6, -0.9, 0.38).normalize().multiplyScalar(distance);
    this.camera.position.copy(look).add(from);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.target.copy(look);
    this.controls.update();
    this.controls.addEventListener("change", () => (this.dirty = true));
    this.tool.position.set(centre.x, centre.y, info.touchHeight);
    this.resize();
    new ResizeObserver(() => this.resize()).observe(canvas);
  }

  private resize(): void {
    const w = this.canvas.clientWidth || 640;
    const h = this.canvas.clientHeight || 480;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  // Takes a frame's positions, field, tool and contacts; returns the field's largest value.
  update(frame: FrameData): number {
    let fieldMax = 0;
    if (frame.positions && frame.positions.length === this.positions.length) {
      this.positions.set(frame.positions);
      this.geometry.attributes.position.needsUpdate = true;
      if (this.surface) this.geometry.computeVertexNormals();
      this.geometry.computeBoundingSphere();
    }
    if (frame.field && 3 * frame.field.length === this.colours.length) {
      for (let k = 0; k < frame.field.length; k++) fieldMax = Math.max(fieldMax, frame.field[k]);
      // The bar's top follows the field up at once and down slowly (no flicker).
      this.fieldRange = Math.max(fieldMax, 0.98 * this.fieldRange, 1e-30);
      for (let k = 0; k < frame.field.length; k++) colour(frame.field[k] / this.fieldRange, this.colours, 3 * k);
      this.geometry.attributes.color.needsUpdate = true;
    }
    const [x, y, z] = frame.indenterPosition;
    this.tool.position.set(x, y, z);
    const f = frame.toolContactForce;
    const magnitude = Math.hypot(f[0], f[1], f[2]);
    this.forceScale = Math.max(this.forceScale, magnitude);
    this.arrow.visible = magnitude > 1e-9 * Math.max(this.forceScale, 1e-30);
    if (this.arrow.visible) {
      const r = this.info.radius;
      const direction = new THREE.Vector3(f[0], f[1], f[2]).normalize();
      // From the point of the tool facing the body, out along the force on the tool.
      this.arrow.position.set(x - r * direction.x, y - r * direction.y, z - r * direction.z);
      this.arrow.setDirection(direction);
      const length = 1.5 * r * (magnitude / this.forceScale);
      this.arrow.setLength(Math.max(length, 0.3 * r), 0.3 * r, 0.18 * r);
    }
    let shown = 0;
    for (let c = 0; c < frame.contactNodes.length && shown < this.patchPositions.length / 3; c++) {
      const k = this.localIndex[frame.contactNodes[c]];
      if (k < 0) continue;
      for (let d = 0; d < 3; d++) this.patchPositions[3 * shown + d] = this.positions[3 * k + d];
      shown++;
    }
    this.patch.geometry.setDrawRange(0, shown);
    this.patch.geometry.attributes.position.needsUpdate = true;
    this.dirty = true;
    return fieldMax;
  }

  // The point of the body's surface under the pointer (NDC coordinates), if any.
  pick(ndcX: number, ndcY: number): THREE.Vector3 | null {
    const ray = new THREE.Raycaster();
    ray.setFromCamera(new THREE.Vector2(ndcX, ndcY), this.camera);
    const hits = ray.intersectObject(this.body, false);
    return hits.length > 0 ? hits[0].point : null;
  }

  render(): void {
    if (!this.dirty) return;
    this.dirty = false;
    this.renderer.render(this.scene, this.camera);
  }

  // Largest displacement of the drawn vertices from the reference configuration, m.
  maxDisplacement(): number {
    const sent = this.surface ? this.info.surfaceVertices : null;
    let worst = 0;
    for (let k = 0; k < this.positions.length / 3; k++) {
      const p = sent ? sent[k] : k;
      const dx = this.positions[3 * k] - this.info.restPositions[3 * p];
      const dy = this.positions[3 * k + 1] - this.info.restPositions[3 * p + 1];
      const dz = this.positions[3 * k + 2] - this.info.restPositions[3 * p + 2];
      worst = Math.max(worst, Math.hypot(dx, dy, dz));
    }
    return worst;
  }
}
