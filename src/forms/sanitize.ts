import DOMPurify, { type DOMPurify as DOMPurifyInstance } from 'dompurify';

/**
 * Descriptions are HTML from the controller: untrusted. Two passes, never raw `innerHTML`:
 * 1. DOMPurify (the well-kept sanitizer) with a short allow-list;
 * 2. a strict rebuild: the result is parsed inertly (DOMParser) and copied node by node into a
 *    fresh tree, keeping only allowed elements and attributes. In a browser this changes nothing
 *    after DOMPurify; it guarantees the allow-list where DOMPurify cannot work fully (test DOMs).
 * Images (Prunt's `<image src="extras/images/stepper_1.png">`, read as `<img>`) may only come from
 * the controller itself: relative sources are resolved against `assetBase` (the machine's
 * `/machines/<id>` prefix); any other source is dropped. Inline styles are dropped (they could
 * cover the page); CSS keeps images within the panel.
 */

const ALLOWED_TAGS = [
  'p',
  'br',
  'b',
  'strong',
  'i',
  'em',
  'u',
  'ul',
  'ol',
  'li',
  'code',
  'pre',
  'a',
  'img',
  'span',
  'sub',
  'sup',
];
const ALLOWED_ATTR = ['src', 'alt', 'href', 'title'];
/** Elements dropped with their content (everything else not allowed is unwrapped). */
const DROP_WITH_CONTENT = new Set([
  'script',
  'style',
  'iframe',
  'object',
  'embed',
  'template',
  'noscript',
  'textarea',
  'select',
  'svg',
  'math',
  'head',
  'title',
]);

let purifier: DOMPurifyInstance | null | undefined;

function instance(): DOMPurifyInstance | null {
  if (purifier !== undefined) return purifier;
  purifier = null;
  if (typeof window === 'undefined') return null;
  const p = DOMPurify(window);
  // Self-test: a DOM where DOMPurify misbehaves (some test DOMs) must not weaken or mangle the
  // result; the strict rebuild then works alone.
  const probe = p.isSupported
    ? String(p.sanitize('<p>a</p><b>b</b><script>x</script><img src="y" onerror="z">'))
    : '';
  purifier = probe === '<p>a</p><b>b</b><img src="y">' ? p : null;
  return purifier;
}

/** Relative paths only ("extras/images/x.png", "/extras/…"), made to go through the machine prefix. */
export function resolveAsset(src: string, base: string): string | null {
  const s = src.trim();
  if (!s || /^[a-z][a-z0-9+.-]*:/i.test(s) || s.startsWith('//') || s.includes('..') || s.includes('\\'))
    return null;
  return `${base.replace(/\/$/, '')}/${s.replace(/^\.?\//, '')}`;
}

function safeHref(href: string): string | null {
  const h = href.trim();
  return /^(https?:|mailto:)/i.test(h) ? h : null;
}

function rebuild(html: string, base: string): string {
  const src = new DOMParser().parseFromString(`<!doctype html><body>${html}`, 'text/html');
  const out = document.createElement('div');
  const copy = (from: Node, to: Node) => {
    for (const child of Array.from(from.childNodes)) {
      if (child.nodeType === 3) {
        to.appendChild(document.createTextNode(child.textContent ?? ''));
        continue;
      }
      if (child.nodeType !== 1) continue; // comments, processing instructions
      const el = child as Element;
      let tag = el.nodeName.toLowerCase();
      if (tag === 'image') tag = 'img';
      if (DROP_WITH_CONTENT.has(tag)) continue;
      if (!ALLOWED_TAGS.includes(tag)) {
        copy(el, to); // unwrap: keep the text
        continue;
      }
      const n = document.createElement(tag);
      for (const a of ALLOWED_ATTR) {
        const v = el.getAttribute(a);
        if (v === null) continue;
        if (a === 'src') {
          if (tag !== 'img') continue;
          const r = resolveAsset(v, base);
          if (r) n.setAttribute('src', r);
        } else if (a === 'href') {
          if (tag !== 'a') continue;
          const h = safeHref(v);
          if (h) n.setAttribute('href', h);
        } else n.setAttribute(a, v);
      }
      if (tag === 'img') {
        if (!n.getAttribute('src')) continue;
        if (!n.getAttribute('alt')) n.setAttribute('alt', 'Board documentation image');
      }
      if (tag === 'a') {
        n.setAttribute('target', '_blank');
        n.setAttribute('rel', 'noopener noreferrer');
      }
      to.appendChild(n);
      copy(el, n);
    }
  };
  copy(src.body, out);
  return out.innerHTML;
}

/** Sanitized HTML, or escaped text when no DOM is available (Node): never unsanitized markup. */
export function sanitizeHtml(html: string, assetBase = ''): string {
  if (typeof document === 'undefined' || typeof DOMParser === 'undefined')
    return escapeHtml(html.replace(/<[^>]*>/g, ' '));
  // Browsers parse Prunt's <image> as <img>; say so explicitly so DOMPurify sees an <img>.
  const input = html.replace(/<image\b/gi, '<img').replace(/<\/image>/gi, '');
  const p = instance();
  const first = p
    ? p.sanitize(input, { ALLOWED_TAGS, ALLOWED_ATTR, ALLOW_DATA_ATTR: false, KEEP_CONTENT: true })
    : input;
  return rebuild(String(first), assetBase);
}

export function escapeHtml(s: string): string {
  return s.replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
}
