// The Browse screen (the collection by label, paged, as thumbnails) and
// the model page (signature summary, 3D view, neighbours).
import * as api from './api';
import { el, showMessage } from './dom';
import { cardsOf, renderGrid } from './results';
import { showPreview } from './search';
import type { Viewer } from './viewer';

const PAGE_SIZE = 24;
let viewer: Viewer | null = null;

export function leaveBrowse(): void {
  viewer?.dispose();
  viewer = null;
}

function go(id: string): void {
  location.hash = `#/model/${encodeURIComponent(id)}`;
}

export function renderBrowse(main: HTMLElement, labels: string[], label: string): void {
  leaveBrowse();
  const select = el('select', { id: 'browse-label' }, el('option', { value: '' }, 'every label'));
  for (const l of labels) select.append(el('option', { value: l, selected: l === label }, l));
  const grid = el('div', { class: 'browse-grid' });
  const prev = el('button', { type: 'button', id: 'prev-page', disabled: true }, 'Previous page');
  const next = el('button', { type: 'button', id: 'next-page', disabled: true }, 'Next page');
  const where = el('span', { 'aria-live': 'polite' });
  main.replaceChildren(
    el('h2', { tabindex: -1 }, 'Browse'),
    el('div', { class: 'field' }, el('label', { for: 'browse-label' }, 'Label'), select),
    grid,
    el('div', { class: 'pager' }, prev, where, next),
  );
  const tokens: string[] = [''];
  let page = 0;
  let nextToken = '';
  const load = async () => {
    try {
      const reply = await api.listModels(select.value, PAGE_SIZE, tokens[page]);
      nextToken = reply.nextPageToken;
      prev.disabled = page === 0;
      next.disabled = !nextToken;
      where.textContent = `Page ${page + 1}`;
      void renderGrid(grid, reply.models.map((m) => ({ id: m.id, label: m.label })), (c) => go(c.id), 'Models');
    } catch (error) {
      grid.replaceChildren();
      showMessage(api.describe(error, 'Listing the models'));
    }
  };
  select.addEventListener('change', () => {
    location.hash = select.value ? `#/browse/${encodeURIComponent(select.value)}` : '#/browse';
  });
  prev.addEventListener('click', () => {
    if (page > 0) {
      --page;
      void load();
    }
  });
  next.addEventListener('click', () => {
    if (!nextToken) return;
    ++page;
    tokens[page] = nextToken;
    void load();
  });
  void load();
}

function summary(model: api.Model): HTMLElement {
  const s = model.signature;
  const features = s?.features ?? [];
  const points = features.filter((f) => f.kind === 'FEATURE_KIND_POINT');
  const rings = features.filter((f) => f.kind === 'FEATURE_KIND_RING');
  const rows: [string, string][] = [
    ['Label', model.label || '(none)'],
    ['Topological points', String(points.length)],
    ['Topological rings', String(rings.length)],
    ['Vertices', s?.mesh?.vertices ?? '?'],
    ['Faces', s?.mesh?.faces ?? '?'],
    ['Genus', s?.mesh?.genus ?? '?'],
    ['Components', s?.mesh?.components ?? '?'],
    ['Spectrum eigenvalues', String(s?.spectrum?.length ?? 0)],
    ['Extractor', s?.extractorVersion ?? '?'],
  ];
  const table = el('table', { class: 'summary' }, el('caption', {}, 'Signature'));
  for (const [k, v] of rows) table.append(el('tr', {}, el('th', { scope: 'row' }, k), el('td', {}, v)));
  const weights = el('table', { class: 'features' }, el('caption', {}, 'Features'));
  weights.append(el('tr', {}, el('th', { scope: 'col' }, 'Kind'), el('th', { scope: 'col' }, 'Weight'), el('th', { scope: 'col' }, 'Integral geodesic')));
  for (const f of features) {
    weights.append(
      el('tr', {}, el('td', {}, f.kind === 'FEATURE_KIND_POINT' ? 'point' : 'ring'), el('td', {}, f.weight.toFixed(4)), el('td', {}, f.integralGeodesic.toFixed(4))),
    );
  }
  return el('div', { class: 'signature' }, table, weights);
}

export async function renderModel(main: HTMLElement, id: string): Promise<void> {
  leaveBrowse();
  const view = el('section', { class: 'model-view', 'aria-label': '3D view' });
  const neighbours = el('section', { 'aria-label': 'Neighbours' });
  const heading = el('h2', { tabindex: -1 }, id);
  main.replaceChildren(heading, el('p', {}, el('a', { href: '#/browse' }, 'Back to Browse')));
  try {
    const model = await api.getModel(id);
    main.append(el('div', { class: 'split' }, view, summary(model)), neighbours);
  } catch (error) {
    showMessage(api.describe(error, `Opening ${id}`));
    return;
  }
  neighbours.append(el('h3', {}, 'Nearest models'));
  const grid = el('div');
  neighbours.append(grid);
  try {
    const reply = await api.searchById(id, { k: 12, label: '', intent: '', excludeSelf: true });
    // The thumbnails first, then the 3D view (see search.ts).
    await renderGrid(grid, cardsOf(reply.neighbors), (c) => go(c.id), 'Nearest models');
  } catch (error) {
    showMessage(api.describe(error, `Searching near ${id}`));
  }
  viewer = await showPreview(view, id);
}
