// The console in a real browser: Debian's Chromium (headless, software
// WebGL) driven by playwright-core, against real tpr-extractor, tpr-indexer
// and tpr-web processes on loopback. A user's path: open the console, drop
// a mesh that is not in the index, see its neighbours appear with their
// thumbnails, open one, filter by label, browse, read the status page, see
// a refused mesh explained. Screenshots go to OUT (kept as test artefacts);
// OUT/timings.json holds the first-screen and 24-thumbnail times the
// console measures with the performance API (docs/benchmarks.md).
//
//   node tests/web/console_browser_test.mjs BUILD_DIR CONSOLE_SOURCE_DIR OUT
// Exit 0 pass, 1 fail, 77 skip (no Chromium or no playwright-core).
import { spawn, spawnSync } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';

const [build, consoleSource, out] = process.argv.slice(2);
const CHROMIUM = '/usr/bin/chromium';
if (!existsSync(CHROMIUM)) {
  console.log(`SKIP: ${CHROMIUM} is not installed (Debian package chromium)`);
  process.exit(77);
}
let chromium;
try {
  chromium = createRequire(resolve(consoleSource, 'package.json'))('playwright-core').chromium;
} catch {
  console.log(`SKIP: playwright-core is not installed (npm ci in ${consoleSource})`);
  process.exit(77);
}
if (!existsSync(join(build, 'web/console/index.html'))) {
  console.log('SKIP: the console is not built (no build/web/console/index.html: npm or npm ci missing, see scripts/setup)');
  process.exit(77);
}
mkdirSync(out, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'tpr-browser-'));
const children = [];
let failed = false;

function bin(name) {
  for (const sub of ['', 'extractor', 'indexer', 'client', 'web', 'extractor/synth']) {
    const p = join(build, sub, name);
    if (existsSync(p)) return p;
  }
  throw new Error(`${name} was not built`);
}

// start runs a service with --listen 127.0.0.1:0 and resolves to its port.
function start(name, args) {
  return new Promise((resolve, reject) => {
    const child = spawn(bin(name), [...args, '--listen', '127.0.0.1:0'], { stdio: ['ignore', 'ignore', 'pipe'] });
    children.push(child);
    let log = '';
    child.stderr.on('data', (chunk) => {
      log += chunk;
      const m = /\(port (\d+)\)/.exec(log);
      if (m) resolve(Number(m[1]));
    });
    child.on('exit', (code) => reject(new Error(`${name} exited ${code}: ${log}`)));
  });
}

function check(condition, what) {
  console.log(`${condition ? 'ok  ' : 'FAIL'} ${what}`);
  if (!condition) failed = true;
}

async function main() {
  // 8 classes x 5 poses; poses 0-3 go into the index, pose 4 is the query.
  const shapes = join(work, 'shapes');
  const synth = spawnSync(bin('tpr-synth'), ['--out', shapes, '--classes', '8', '--poses', '5', '--vertices', '1500', '--seed', '1']);
  if (synth.status !== 0) throw new Error(`tpr-synth failed: ${synth.stderr}`);
  const manifest = readFileSync(join(shapes, 'MANIFEST.txt'), 'utf8')
    .trim()
    .split('\n')
    .map((line) => line.split(/\s+/));
  const extractor = await start('tpr-extractor', ['--threads', '2']);
  const indexer = await start('tpr-indexer', ['--data-dir', join(work, 'data')]);
  const web = await start('tpr-web', ['--extractor', `127.0.0.1:${extractor}`, '--indexer', `127.0.0.1:${indexer}`, '--console-dir', join(build, 'web/console')]);
  const base = `http://127.0.0.1:${web}`;
  const stored = manifest.filter(([id]) => !/_4\.off$/.test(id));
  const queries = manifest.filter(([id]) => /_4\.off$/.test(id));
  for (const [id, label] of stored) {
    const form = new FormData();
    form.append('mesh', new Blob([readFileSync(join(shapes, id))]), id);
    const r = await fetch(`${base}/api/v1/models?${new URLSearchParams({ id, label, overwrite: '1' })}`, { method: 'POST', body: form });
    if (!r.ok) throw new Error(`adding ${id}: ${r.status} ${await r.text()}`);
  }
  const thumbProbe = await fetch(`${base}/api/v1/thumbnails/${encodeURIComponent(stored[0][0])}`);
  const mediaServed = thumbProbe.status === 200;
  console.log(`the indexer ${mediaServed ? 'serves' : `does not serve (HTTP ${thumbProbe.status})`} thumbnails`);

  const browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync', '--enable-unsafe-swiftshader'],
  });
  const page = await browser.newPage({ viewport: { width: 1280, height: 1000 } });
  const consoleErrors = [];
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  const timings = {};

  // First screen.
  await page.goto(`${base}/`);
  await page.waitForFunction(() => performance.getEntriesByName('tpr-first-screen').length > 0);
  timings.firstScreenMs = await page.evaluate(() => performance.getEntriesByName('tpr-first-screen')[0].startTime);
  check(await page.isVisible('#mesh-file'), 'the Search screen shows the mesh picker');
  await page.screenshot({ path: join(out, '01-search.png') });

  // Drop a mesh that is not in the index (the file input, as a keyboard
  // user would choose it).
  const [queryId, queryLabel] = queries[0];
  await page.setInputFiles('#mesh-file', join(shapes, queryId));
  await page.waitForSelector('.results .grid[data-thumbnails="done"]', { timeout: 60000 });
  timings.thumbnails = await page.evaluate(() => {
    const m = performance.getEntriesByName('tpr-thumbnails')[0];
    return { count: document.querySelectorAll('.results .card').length, ms: m.duration };
  });
  const cards = await page.$$eval('.results .card', (els) => els.map((e) => ({ id: e.dataset.id, text: e.textContent })));
  check(cards.length === 24, `24 neighbours shown (got ${cards.length})`);
  check(cards[0]?.id.startsWith(`${queryLabel}/`), `the nearest model has the query's class ${queryLabel} (got ${cards[0]?.id})`);
  const images = await page.$$eval('.results .card img', (els) => els.filter((i) => i.naturalWidth > 0).length);
  if (mediaServed) check(images === 24, `24 thumbnails drawn (got ${images})`);
  else check(images === 0 && (await page.isVisible('.results .placeholder')), 'without media, every card says it has no picture');
  await page.waitForSelector('.query canvas', { timeout: 30000 });
  check(await page.isVisible('.query canvas'), 'the query is drawn in 3D');
  const overlay = await page.textContent('.query p');
  check(/\d+ topological points/.test(overlay ?? ''), `the query's features are listed (${overlay})`);
  await page.screenshot({ path: join(out, '02-results.png'), fullPage: true });

  // The same mesh as OBJ: the same nearest model.
  const off = readFileSync(join(shapes, queryId), 'utf8').split('\n').filter((l) => l.trim() && !l.startsWith('OFF'));
  const [nv] = off[0].split(/\s+/).map(Number);
  const obj = [...off.slice(1, 1 + nv).map((l) => `v ${l}`), ...off.slice(1 + nv).map((l) => `f ${l.trim().split(/\s+/).slice(1).map((i) => Number(i) + 1).join(' ')}`)].join('\n');
  await page.setInputFiles('#mesh-file', { name: 'query.obj', mimeType: 'text/plain', buffer: Buffer.from(obj) });
  await page.waitForSelector('.query h3 >> text=query.obj');
  await page.waitForSelector('.results .grid[data-thumbnails="done"]', { timeout: 60000 });
  await page.waitForSelector('.query canvas', { timeout: 30000 });
  const objFirst = await page.$eval('.results .card', (e) => e.dataset.id);
  check(objFirst === cards[0]?.id, `the OBJ upload finds the same nearest model (${objFirst})`);
  await page.screenshot({ path: join(out, '02b-obj-results.png') });

  // Open one neighbour: its own 3D view (its preview mesh).
  await page.focus('.results .card >> nth=1');
  await page.keyboard.press('Enter');
  await page.waitForSelector('.opened h3');
  if (mediaServed) {
    await page.waitForSelector('.opened canvas', { timeout: 30000 });
    check(true, 'the opened neighbour has a 3D view');
  } else {
    await page.waitForSelector('.opened .note');
    check(true, 'the opened neighbour explains why it has no 3D view');
  }
  await page.screenshot({ path: join(out, '03-opened.png'), fullPage: true });

  // Filter by label, querying by a stored model's id.
  const otherLabel = manifest.find(([, l]) => l !== queryLabel)[1];
  await page.fill('#model-id', stored[0][0]);
  await page.selectOption('#label', otherLabel);
  await page.fill('#k', '24');
  await page.click('#search-button');
  await page.waitForFunction((l) => {
    const c = [...document.querySelectorAll('.results .card')];
    return c.length > 0 && c.every((e) => e.textContent.includes(l));
  }, otherLabel, { timeout: 30000 });
  const filtered = await page.$$eval('.results .card', (els) => els.map((e) => e.textContent));
  check(filtered.length === 4 && filtered.every((t) => t.includes(otherLabel)), `label filter ${otherLabel}: ${filtered.length} models, all of it`);
  await page.screenshot({ path: join(out, '04-label-filter.png'), fullPage: true });

  // Browse by label, then a model page.
  await page.click('nav a[data-screen="browse"]');
  await page.waitForSelector('.browse-grid .card');
  await page.selectOption('#browse-label', queryLabel);
  await page.waitForFunction((l) => {
    const c = [...document.querySelectorAll('.browse-grid .card')];
    return c.length === 4 && c.every((e) => e.textContent.includes(l));
  }, queryLabel);
  check(true, `Browse lists the 4 models labelled ${queryLabel}`);
  await page.screenshot({ path: join(out, '05-browse.png'), fullPage: true });
  await page.click('.browse-grid .card >> nth=0');
  await page.waitForSelector('table.summary');
  const summary = await page.textContent('table.summary');
  check(/Topological points\d+/.test(summary ?? ''), 'the model page shows its signature summary');
  await page.waitForSelector('section[aria-label="Neighbours"] .card');
  await page.screenshot({ path: join(out, '06-model.png'), fullPage: true });

  // Status.
  await page.click('nav a[data-screen="status"]');
  await page.waitForSelector('.status table');
  const status = await page.textContent('.status');
  check(/tpr-extractor.*ready/.test(status ?? '') && /tpr-indexer.*ready/.test(status ?? ''), 'Status: both services ready');
  check((status ?? '').includes(String(stored.length)), `Status: ${stored.length} models`);
  await page.screenshot({ path: join(out, '07-status.png'), fullPage: true });

  // A refused mesh is explained.
  await page.click('nav a[data-screen="search"]');
  await page.waitForSelector('#mesh-file');
  await page.setInputFiles('#mesh-file', { name: 'broken.off', mimeType: 'application/octet-stream', buffer: Buffer.from('OFF\n3 1 0\n0 0 0\n1 0 0\n') });
  await page.waitForSelector('#message:not([hidden])');
  const message = await page.textContent('#message');
  check(/refused/.test(message ?? '') && /broken\.off/.test(message ?? ''), `a broken mesh is refused with a reason: ${message}`);
  await page.screenshot({ path: join(out, '08-refused.png'), fullPage: true });

  // Keyboard only: Tab from the top reaches the mesh picker and the Search
  // button, each with a visible label.
  await page.goto(`${base}/#/search`);
  await page.waitForSelector('#mesh-file');
  await page.evaluate(() => document.activeElement?.blur());
  const reached = [];
  for (let i = 0; i < 20; ++i) {
    await page.keyboard.press('Tab');
    reached.push(await page.evaluate(() => document.activeElement?.id || document.activeElement?.tagName.toLowerCase() || ''));
  }
  check(reached.includes('mesh-file') && reached.includes('search-button') && reached.indexOf('mesh-file') < reached.indexOf('search-button'), `Tab reaches the mesh picker, then Search (${reached.join(' > ')})`);
  const unlabelled = await page.$$eval('input, select', (els) => els.filter((e) => !e.labels || e.labels.length === 0).map((e) => e.id));
  check(unlabelled.length === 0, `every input has a label (${unlabelled.join(', ')})`);

  // A tpr-web that requires keys: the console says a key is missing, and
  // works once one is entered.
  const keys = join(work, 'keys.txt');
  const made = spawnSync(bin('tpr'), ['key', 'new', '--role', 'read', '--keys', keys]);
  const key = String(made.stdout).trim();
  const locked = await start('tpr-web', ['--extractor', `127.0.0.1:${extractor}`, '--indexer', `127.0.0.1:${indexer}`, '--console-dir', join(build, 'web/console'), '--api-keys', keys]);
  await page.goto(`http://127.0.0.1:${locked}/`);
  await page.waitForSelector('#message:not([hidden])');
  const keyMessage = await page.textContent('#message');
  check(/needs an API key/.test(keyMessage ?? ''), `without a key the console says so: ${keyMessage}`);
  await page.screenshot({ path: join(out, '09-key-missing.png') });
  await page.fill('#api-key', key);
  await page.press('#api-key', 'Enter');
  await page.waitForSelector('#message', { state: 'hidden' });
  const labelled = await page.$$eval('#label option', (els) => els.length);
  check(labelled === 9, `with the key the labels load (${labelled - 1} labels)`);

  check(consoleErrors.length === 0, `no script errors (${consoleErrors.join('; ')})`);
  await browser.close();
  writeFileSync(join(out, 'timings.json'), `${JSON.stringify(timings, null, 2)}\n`);
  console.log(`timings: first screen ${timings.firstScreenMs.toFixed(0)} ms; ${timings.thumbnails.count} thumbnails in ${timings.thumbnails.ms.toFixed(0)} ms`);
}

try {
  await main();
} catch (error) {
  console.log(`FAIL: ${error.stack ?? error}`);
  failed = true;
} finally {
  // The indexer saves its tree on SIGTERM: wait for every exit before
  // removing the directory it writes to.
  await Promise.all(
    children.map(
      (c) =>
        new Promise((done) => {
          if (c.exitCode !== null || c.signalCode !== null) return done();
          c.once('exit', done);
          c.kill('SIGTERM');
        }),
    ),
  );
  rmSync(work, { recursive: true, force: true });
}
process.exit(failed ? 1 : 0);
