// The Status screen: both services' readiness, the index's counts (per
// shard behind a gateway), and the query rate and latency of the searches
// made through tpr-web (the indexer's own SearchStats time and the whole
// request's). Refreshes every 5 s while shown.
import * as api from './api';
import { el, showMessage } from './dom';

let timer = 0;

export function leaveStatus(): void {
  window.clearInterval(timer);
  timer = 0;
}

function mib(bytes: string | undefined): string {
  return `${(Number(bytes ?? 0) / (1 << 20)).toFixed(1)} MiB`;
}

function table(caption: string, head: string[], rows: string[][]): HTMLElement {
  const t = el('table', {}, el('caption', {}, caption));
  t.append(el('tr', {}, ...head.map((h) => el('th', { scope: 'col' }, h))));
  for (const r of rows) t.append(el('tr', {}, ...r.map((c) => el('td', {}, c))));
  return t;
}

function draw(body: HTMLElement, s: api.StatusReply): void {
  const service = (name: string, x: api.ServiceState) => [name, x.address, x.ready ? 'ready' : `not ready: ${x.reason}`];
  const parts: HTMLElement[] = [
    table('Services', ['Service', 'Address', 'Readiness'], [service('tpr-extractor', s.extractor), service('tpr-indexer', s.indexer)]),
  ];
  if (s.stats) {
    const st = s.stats;
    parts.push(
      table('Index', ['Models', 'Indexed', 'Buffered', 'Memory', 'Disk'], [[st.models, st.indexed, st.buffered, mib(st.memoryBytes), mib(st.diskBytes)]]),
    );
    if (st.shards.length > 0) {
      parts.push(
        table(
          'Shards',
          ['Shard', 'Replica answering', 'Models', 'Buffered'],
          st.shards.map((sh) => [String(sh.shard), sh.address, sh.stats.models, sh.stats.buffered]),
        ),
      );
    }
    const labels = Object.entries(st.labels).sort((a, b) => Number(b[1]) - Number(a[1]));
    parts.push(table('Labels', ['Label', 'Models'], labels.map(([l, n]) => [l || '(none)', n])));
  } else if (s.statsError) {
    parts.push(el('p', { class: 'warning' }, `Index statistics unavailable: ${s.statsError.code}: ${s.statsError.message}`));
  }
  const q = s.searches;
  parts.push(
    table(
      `Searches through tpr-web (last ${q.windowSeconds} s)`,
      ['Total', 'In window', 'Per second', 'Indexer p50', 'Indexer p95', 'Request p50', 'Request p95'],
      [[String(q.total), String(q.inWindow), q.perSecond.toFixed(2), `${q.indexerP50Ms.toFixed(2)} ms`, `${q.indexerP95Ms.toFixed(2)} ms`, `${q.p50Ms.toFixed(2)} ms`, `${q.p95Ms.toFixed(2)} ms`]],
    ),
  );
  body.replaceChildren(...parts);
}

export function renderStatus(main: HTMLElement): void {
  leaveStatus();
  const body = el('div', { class: 'status', 'aria-live': 'polite' });
  const refresh = el('button', { type: 'button', id: 'refresh' }, 'Refresh');
  main.replaceChildren(el('h2', { tabindex: -1 }, 'Status'), refresh, body);
  const load = async () => {
    try {
      draw(body, await api.status());
    } catch (error) {
      showMessage(api.describe(error, 'Reading the status'));
    }
  };
  refresh.addEventListener('click', () => void load());
  timer = window.setInterval(() => void load(), 5000);
  void load();
}
