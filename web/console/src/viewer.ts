// A 3D view of one mesh (three.js) with its TPR overlay: topological points
// as red dots, topological rings as blue loops. Renders on demand (after a
// drag, a zoom or a key), so an idle page costs nothing.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { OBJLoader } from 'three/examples/jsm/loaders/OBJLoader.js';
import { PLYLoader } from 'three/examples/jsm/loaders/PLYLoader.js';
import { STLLoader } from 'three/examples/jsm/loaders/STLLoader.js';

export interface Overlay {
  points: THREE.Vector3[];
  rings: THREE.Vector3[][];
}

// parseOff reads an ASCII OFF file (three.js has no OFF loader), keeping
// the vertex order, so that the extractor's vertex indices apply.
export function parseOff(text: string): THREE.BufferGeometry {
  const tokens = text
    .split('\n')
    .map((line) => line.replace(/#.*/, '').trim())
    .filter((line) => line.length > 0)
    .join(' ')
    .split(/\s+/);
  let at = 0;
  const header = tokens[at++];
  if (!/^N?C?OFF$/.test(header ?? '')) throw new Error('not an OFF file (no OFF header)');
  const nv = Number(tokens[at++]);
  const nf = Number(tokens[at++]);
  at++; // edge count
  if (!Number.isInteger(nv) || !Number.isInteger(nf)) throw new Error('OFF header counts are not integers');
  const positions = new Float32Array(nv * 3);
  for (let i = 0; i < nv * 3; ++i) positions[i] = Number(tokens[at++]);
  const index: number[] = [];
  for (let f = 0; f < nf; ++f) {
    const n = Number(tokens[at++]);
    const face: number[] = [];
    for (let j = 0; j < n; ++j) face.push(Number(tokens[at++]));
    for (let j = 1; j + 1 < n; ++j) index.push(face[0], face[j], face[j + 1]);
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  geometry.setIndex(index);
  return geometry;
}

// geometryFromFile reads OFF, OBJ, PLY or STL by the file name's extension.
export function geometryFromFile(name: string, data: ArrayBuffer): THREE.BufferGeometry {
  const ext = name.toLowerCase().split('.').pop() ?? '';
  switch (ext) {
    case 'off':
      return parseOff(new TextDecoder().decode(data));
    case 'obj': {
      const group = new OBJLoader().parse(new TextDecoder().decode(data));
      let found: THREE.BufferGeometry | null = null;
      group.traverse((child) => {
        if (!found && child instanceof THREE.Mesh) found = child.geometry as THREE.BufferGeometry;
      });
      if (!found) throw new Error('the OBJ file has no faces');
      return found;
    }
    case 'ply':
      return new PLYLoader().parse(data);
    case 'stl':
      return new STLLoader().parse(data);
    default:
      throw new Error(`cannot display .${ext} files (OFF, OBJ, PLY, STL)`);
  }
}

// OrderLoop orders a ring's vertices into a loop, each followed by the
// nearest one not yet taken (the extractor lists a wavefront's vertices,
// not necessarily in order along it).
function orderLoop(points: THREE.Vector3[]): THREE.Vector3[] {
  if (points.length < 3) return points;
  const left = points.slice(1);
  const out = [points[0]];
  while (left.length > 0) {
    const last = out[out.length - 1];
    let best = 0;
    for (let i = 1; i < left.length; ++i) {
      if (left[i].distanceToSquared(last) < left[best].distanceToSquared(last)) best = i;
    }
    out.push(left.splice(best, 1)[0]);
  }
  return out;
}

export class Viewer {
  private renderer: THREE.WebGLRenderer | null = null;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(35, 4 / 3, 0.01, 1000);
  private controls: OrbitControls | null = null;
  readonly element: HTMLElement;

  constructor(container: HTMLElement, label: string, width = 480, height = 360) {
    this.element = document.createElement('div');
    this.element.className = 'viewer';
    container.appendChild(this.element);
    try {
      this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    } catch {
      this.element.textContent = 'The 3D view needs WebGL, which this browser does not offer.';
      return;
    }
    this.renderer.setSize(width, height);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    const canvas = this.renderer.domElement;
    canvas.tabIndex = 0;
    canvas.setAttribute('role', 'img');
    canvas.setAttribute('aria-label', `${label}. Drag or use the arrow keys to move the view, the mouse wheel to zoom.`);
    this.element.appendChild(canvas);
    this.scene.background = new THREE.Color(0xf4f5f7);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x667788, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(1, 2, 3);
    this.camera.add(sun);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.listenToKeyEvents(canvas);
    this.controls.addEventListener('change', () => this.render());
  }

  show(geometry: THREE.BufferGeometry, overlay?: Overlay): void {
    if (!this.renderer || !this.controls) return;
    if (!geometry.getAttribute('normal')) geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
    const sphere = geometry.boundingSphere ?? new THREE.Sphere(new THREE.Vector3(), 1);
    const mesh = new THREE.Mesh(
      geometry,
      new THREE.MeshStandardMaterial({ color: 0xc9ced6, roughness: 0.8, metalness: 0, side: THREE.DoubleSide }),
    );
    this.scene.add(mesh);
    const r = sphere.radius || 1;
    if (overlay) {
      const dot = new THREE.SphereGeometry(r * 0.03, 12, 8);
      const red = new THREE.MeshBasicMaterial({ color: 0xd62828 });
      for (const p of overlay.points) {
        const m = new THREE.Mesh(dot, red);
        m.position.copy(p);
        this.scene.add(m);
      }
      const blue = new THREE.LineBasicMaterial({ color: 0x1d4ed8, depthTest: false });
      for (const ring of overlay.rings) {
        const loop = new THREE.LineLoop(new THREE.BufferGeometry().setFromPoints(orderLoop(ring)), blue);
        loop.renderOrder = 1;
        this.scene.add(loop);
      }
    }
    const c = sphere.center;
    this.camera.near = r / 100;
    this.camera.far = r * 100;
    this.camera.position.set(c.x + r * 1.6, c.y + r * 1.2, c.z + r * 2.6);
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(c);
    this.controls.update();
    this.render();
  }

  render(): void {
    this.renderer?.render(this.scene, this.camera);
  }

  dispose(): void {
    this.controls?.dispose();
    this.renderer?.dispose();
    this.element.remove();
  }
}
