// Tiny DOM helpers: el('button', {type: 'submit'}, 'Search').
export type Child = Node | string | null | undefined | false;

export function el<K extends keyof HTMLElementTagNameMap>(
  tag: K,
  attrs: Record<string, string | number | boolean | EventListener> = {},
  ...children: Child[]
): HTMLElementTagNameMap[K] {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) {
    if (typeof value === 'function') node.addEventListener(name.replace(/^on/, ''), value);
    else if (value === true) node.setAttribute(name, '');
    else if (value !== false) node.setAttribute(name, String(value));
  }
  for (const child of children) {
    if (child === null || child === undefined || child === false) continue;
    node.append(child);
  }
  return node;
}

// showMessage shows `text` in the page's alert region (empty: hides it).
export function showMessage(text: string): void {
  const box = document.getElementById('message');
  if (!box) return;
  box.textContent = text;
  box.hidden = text.length === 0;
}
