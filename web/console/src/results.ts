// A grid of models as thumbnails with id, label and (for search results)
// rank and distance; each card is a button. Marks when every thumbnail has
// arrived (performance measure "tpr-thumbnails", from "tpr-results").
import { describe, thumbnailUrl, type Neighbor } from './api';
import { el } from './dom';

export interface Card {
  id: string;
  label: string;
  rank?: number;
  distance?: number;
}

export function cardsOf(neighbors: Neighbor[]): Card[] {
  return neighbors.map((n) => ({ id: n.id, label: n.label, rank: n.rank, distance: n.distance }));
}

// renderGrid draws the cards; the promise resolves once every thumbnail has
// arrived (or failed).
export function renderGrid(container: HTMLElement, cards: Card[], onOpen: (card: Card) => void, caption: string): Promise<void> {
  container.replaceChildren();
  if (cards.length === 0) {
    container.append(el('p', {}, 'No models.'));
    return Promise.resolve();
  }
  let finished: () => void = () => undefined;
  const all = new Promise<void>((resolve) => (finished = resolve));
  performance.clearMarks('tpr-results');
  performance.clearMeasures('tpr-thumbnails');
  performance.mark('tpr-results');
  const list = el('ul', { class: 'grid', 'aria-label': caption });
  let pending = cards.length;
  const done = () => {
    if (--pending === 0) {
      performance.measure('tpr-thumbnails', 'tpr-results');
      list.dataset.thumbnails = 'done';
      finished();
    }
  };
  for (const card of cards) {
    const picture = el('div', { class: 'thumb' }, el('span', { class: 'placeholder' }, '…'));
    const title = card.rank !== undefined ? `${card.rank}. ${card.id}` : card.id;
    const details = [card.label || 'no label'];
    if (card.distance !== undefined) details.push(`distance ${card.distance.toFixed(4)}`);
    const button = el(
      'button',
      { type: 'button', class: 'card', 'data-id': card.id, onclick: () => onOpen(card) },
      picture,
      el('span', { class: 'card-title' }, title),
      el('span', { class: 'card-details' }, details.join(' · ')),
    );
    list.append(el('li', {}, button));
    thumbnailUrl(card.id)
      .then((url) => {
        const img = el('img', { src: url, alt: `Thumbnail of ${card.id}`, width: 128, height: 128 });
        img.addEventListener('load', done, { once: true });
        img.addEventListener('error', done, { once: true });
        picture.replaceChildren(img);
      })
      .catch((error: unknown) => {
        picture.replaceChildren(el('span', { class: 'placeholder', title: describe(error, 'Thumbnail') }, 'no picture'));
        done();
      });
  }
  container.append(list);
  return all;
}
