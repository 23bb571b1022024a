// The Search screen: drop a mesh (or pick a stored model), see it in 3D
// with its topological points and rings, and its k nearest models as
// thumbnails; open one for its own 3D view.
import * as THREE from 'three';
import { PLYLoader } from 'three/examples/jsm/loaders/PLYLoader.js';
import * as api from './api';
import { el, showMessage } from './dom';
import { cardsOf, renderGrid, type Card } from './results';
import { geometryFromFile, Viewer, type Overlay } from './viewer';

let viewers: Viewer[] = [];

function clearViewers(): void {
  for (const v of viewers) v.dispose();
  viewers = [];
}

// fileVertices returns a vertex lookup in the file's own order: the
// displayed geometry's for indexed formats (OFF, PLY), the "v" lines for
// OBJ (its loader unrolls faces), none for STL (no shared vertices).
function fileVertices(name: string, bytes: ArrayBuffer, geometry: THREE.BufferGeometry): THREE.Vector3[] | null {
  if (name.toLowerCase().endsWith('.obj')) {
    const out: THREE.Vector3[] = [];
    for (const line of new TextDecoder().decode(bytes).split('\n')) {
      const m = /^v\s+(\S+)\s+(\S+)\s+(\S+)/.exec(line);
      if (m) out.push(new THREE.Vector3(Number(m[1]), Number(m[2]), Number(m[3])));
    }
    return out;
  }
  if (!geometry.index) return null;
  const position = geometry.getAttribute('position');
  const out: THREE.Vector3[] = [];
  for (let i = 0; i < position.count; ++i) out.push(new THREE.Vector3().fromBufferAttribute(position, i));
  return out;
}

// overlayOf places each feature of the query: from the explanation's
// positions when the extractor sent them, else from its vertex indices
// into the file's vertices (the extractor numbers them in file order).
function overlayOf(reply: api.ExtractResponse, vertices: THREE.Vector3[] | null): Overlay {
  const overlay: Overlay = { points: [], rings: [] };
  const features = reply.signature?.features ?? [];
  const placed = reply.explanation?.featureVertices ?? [];
  placed.forEach((f, i) => {
    const pts: THREE.Vector3[] = [];
    const p = f.positions ?? [];
    if (p.length >= 3) {
      for (let j = 0; j + 2 < p.length; j += 3) pts.push(new THREE.Vector3(p[j], p[j + 1], p[j + 2]));
    } else if (vertices) {
      for (const v of f.vertices ?? []) if (v < vertices.length) pts.push(vertices[v]);
    }
    if (pts.length === 0) return;
    if (features[i]?.kind === 'FEATURE_KIND_POINT') overlay.points.push(pts[0]);
    else overlay.rings.push(pts);
  });
  return overlay;
}

export async function showPreview(container: HTMLElement, id: string): Promise<Viewer | null> {
  try {
    const data = await api.preview(id);
    const viewer = new Viewer(container, `3D view of ${id}`);
    viewer.show(new PLYLoader().parse(data));
    return viewer;
  } catch (error) {
    container.append(el('p', { class: 'note' }, api.describe(error, `The 3D view of ${id}`)));
    return null;
  }
}

function options(form: HTMLFormElement): api.SearchOptions {
  const data = new FormData(form);
  return {
    k: Number(data.get('k') ?? 10) || 10,
    label: String(data.get('label') ?? ''),
    intent: String(data.get('intent') ?? ''),
  };
}

export function renderSearch(main: HTMLElement, labels: string[]): void {
  clearViewers();
  const file = el('input', { id: 'mesh-file', name: 'mesh', type: 'file', accept: '.off,.obj,.ply,.stl' });
  const modelId = el('input', { id: 'model-id', name: 'id', type: 'text', list: 'model-ids', autocomplete: 'off' });
  const labelSelect = el('select', { id: 'label', name: 'label' }, el('option', { value: '' }, 'any label'));
  for (const l of labels) labelSelect.append(el('option', { value: l }, l));
  const form = el(
    'form',
    { class: 'search-form', 'aria-label': 'Search' },
    el(
      'div',
      { class: 'drop', id: 'drop' },
      el('label', { for: 'mesh-file' }, 'Mesh file (OFF, OBJ, PLY, STL): drop it here or choose it'),
      file,
    ),
    el('div', { class: 'field' }, el('label', { for: 'model-id' }, 'or a stored model id'), modelId, el('datalist', { id: 'model-ids' })),
    el('div', { class: 'field' }, el('label', { for: 'k' }, 'Neighbours (k)'), el('input', { id: 'k', name: 'k', type: 'number', min: 1, max: 200, value: 24 })),
    el('div', { class: 'field' }, el('label', { for: 'label' }, 'Label filter'), labelSelect),
    el(
      'div',
      { class: 'field' },
      el('label', { for: 'intent' }, 'Intent'),
      el(
        'select',
        { id: 'intent', name: 'intent' },
        el('option', { value: 'balanced' }, 'balanced'),
        el('option', { value: 'identity' }, 'identity: this model in other poses'),
        el('option', { value: 'kind' }, 'kind: models of the same kind'),
      ),
    ),
    el('button', { type: 'submit', id: 'search-button' }, 'Search'),
  );
  const busy = el('p', { class: 'busy', 'aria-live': 'polite', id: 'search-state' });
  const query = el('section', { class: 'query', 'aria-label': 'Query' });
  const results = el('section', { class: 'results', 'aria-label': 'Nearest models' });
  const opened = el('section', { class: 'opened', 'aria-label': 'Opened model' });
  main.replaceChildren(el('h2', { tabindex: -1 }, 'Search'), form, busy, el('div', { class: 'split' }, query, results), opened);

  const drop = form.querySelector('#drop') as HTMLElement;
  drop.addEventListener('dragover', (e) => {
    e.preventDefault();
    drop.classList.add('over');
  });
  drop.addEventListener('dragleave', () => drop.classList.remove('over'));
  drop.addEventListener('drop', (e) => {
    e.preventDefault();
    drop.classList.remove('over');
    if (e.dataTransfer?.files.length) {
      file.files = e.dataTransfer.files;
      form.requestSubmit();
    }
  });
  file.addEventListener('change', () => {
    if (file.files?.length) form.requestSubmit();
  });
  api
    .listModels('', 1000, '')
    .then((page) => {
      const list = form.querySelector('#model-ids') as HTMLElement;
      for (const m of page.models) list.append(el('option', { value: m.id }));
    })
    .catch(() => undefined); // The search itself will say what is wrong.

  const open = async (card: Card) => {
    for (const v of viewers.splice(1)) v.dispose();
    opened.replaceChildren(
      el('h3', { tabindex: -1 }, card.id),
      el('p', {}, `${card.label || 'no label'}${card.distance !== undefined ? ` · distance ${card.distance.toFixed(4)}` : ''} · `, el('a', { href: `#/model/${encodeURIComponent(card.id)}` }, 'model page')),
    );
    (opened.querySelector('h3') as HTMLElement).focus();
    const v = await showPreview(opened, card.id);
    if (v) viewers.push(v);
  };

  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    showMessage('');
    const opts = options(form);
    const chosen = file.files?.[0];
    const id = modelId.value.trim();
    if (!chosen && !id) {
      showMessage('Choose a mesh file or type a stored model id first.');
      return;
    }
    busy.textContent = 'Searching…';
    clearViewers();
    query.replaceChildren();
    results.replaceChildren();
    opened.replaceChildren();
    try {
      let reply: api.SearchReply;
      // The 3D view is drawn after the thumbnails: with software WebGL its
      // first frame holds the page's thread for about 200 ms, which would
      // delay every thumbnail still arriving.
      let draw: () => Promise<void>;
      if (chosen) {
        const bytes = await chosen.arrayBuffer();
        reply = await api.searchByUpload(chosen, opts);
        file.value = '';
        const heading = el('h3', {}, `Query: ${chosen.name}`);
        query.append(heading);
        const features = reply.query?.signature?.features ?? [];
        const points = features.filter((f) => f.kind === 'FEATURE_KIND_POINT').length;
        query.append(el('p', {}, `${points} topological points (red), ${features.length - points} rings (blue)`));
        for (const w of reply.query?.warnings ?? []) query.append(el('p', { class: 'warning' }, w));
        const answer = reply;
        draw = async () => {
          try {
            const geometry = geometryFromFile(chosen.name, bytes);
            const v = new Viewer(query, `3D view of ${chosen.name} with its topological points and rings`);
            v.show(geometry, answer.query ? overlayOf(answer.query, fileVertices(chosen.name, bytes, geometry)) : undefined);
            viewers.unshift(v);
          } catch (error) {
            query.append(el('p', { class: 'note' }, `Cannot display ${chosen.name}: ${String(error)}`));
          }
        };
      } else {
        reply = await api.searchById(id, opts);
        query.append(el('h3', {}, `Query: ${id}`));
        draw = async () => {
          const v = await showPreview(query, id);
          if (v) viewers.unshift(v);
        };
      }
      busy.textContent = `${reply.neighbors.length} nearest models in ${reply.stats.milliseconds.toFixed(1)} ms (indexer time).`;
      results.append(el('h3', {}, 'Nearest models'));
      const grid = el('div');
      results.append(grid);
      await renderGrid(grid, cardsOf(reply.neighbors), open, 'Nearest models');
      await draw();
    } catch (error) {
      busy.textContent = '';
      showMessage(api.describe(error, chosen ? `Searching with ${chosen.name}` : `Searching with ${id}`));
    }
  });
}

export function leaveSearch(): void {
  clearViewers();
}
