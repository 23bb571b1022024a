// The TPR Search console: Search, Browse (and model pages) and Status,
// routed by the URL's hash (#/search, #/browse/LABEL, #/model/ID,
// #/status), over tpr-web's /api/v1. Marks "tpr-first-screen" (performance
// API) once the first screen is drawn.
import './style.css';
import * as api from './api';
import { renderBrowse, renderModel, leaveBrowse } from './browse';
import { showMessage } from './dom';
import { renderSearch, leaveSearch } from './search';
import { renderStatus, leaveStatus } from './status';

const main = document.getElementById('main') as HTMLElement;
let labels: string[] = [];
let first = true;

// loadLabels reads the index's labels; returns what went wrong ("" when
// nothing did).
async function loadLabels(): Promise<string> {
  try {
    const s = await api.stats();
    labels = Object.keys(s.labels)
      .filter((l) => l)
      .sort();
    return '';
  } catch (error) {
    return api.describe(error, 'Reading the index');
  }
}

async function route(problem = ''): Promise<void> {
  leaveSearch();
  leaveBrowse();
  leaveStatus();
  showMessage(problem);
  const hash = location.hash.replace(/^#\/?/, '');
  const [screen, ...rest] = hash.split('/');
  const arg = decodeURIComponent(rest.join('/'));
  for (const a of document.querySelectorAll<HTMLAnchorElement>('nav a')) {
    if (a.dataset.screen === (screen === 'model' ? 'browse' : screen || 'search')) a.setAttribute('aria-current', 'page');
    else a.removeAttribute('aria-current');
  }
  switch (screen) {
    case 'browse':
      renderBrowse(main, labels, arg);
      break;
    case 'model':
      await renderModel(main, arg);
      break;
    case 'status':
      renderStatus(main);
      break;
    default:
      renderSearch(main, labels);
  }
  if (first) {
    first = false;
    performance.mark('tpr-first-screen');
  } else {
    (main.querySelector('h2') as HTMLElement | null)?.focus();
  }
}

const keyForm = document.getElementById('key-form') as HTMLFormElement;
const keyInput = document.getElementById('api-key') as HTMLInputElement;
keyInput.value = api.apiKey();
keyForm.addEventListener('submit', (e) => {
  e.preventDefault();
  api.setApiKey(keyInput.value.trim());
  void loadLabels().then((problem) => route(problem));
});

window.addEventListener('hashchange', () => void route());
void loadLabels().then((problem) => route(problem));
