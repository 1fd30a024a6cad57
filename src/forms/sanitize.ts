import DOMPurify, { type DOMPurify as DOMPurifyInstance } from 'dompurify';
import { resolveWithin, safeExternalHref } from '../ui/safe-url';

/**
 * Descriptions are HTML from the controller: untrusted. Two passes, never raw `innerHTML`:
 * 1. DOMPurify (the well-kept sanitizer) with a short allow-list;
 * 2. a strict rebuild: the result is parsed inertly (DOMParser) and copied node by node into a
 *    fresh tree, keeping only allowed elements and attributes. In a browser this changes nothing
 *    after DOMPurify; it guarantees the allow-list where DOMPurify cannot work fully (test DOMs).
 * Images (Prunt's `<image src="extras/images/stepper_1.png">`, read as `<img>`) may only come from
 * the machine itself: the source is resolved as the browser would against `assetBase` (the
 * machine's `/machines/<id>` prefix) and kept only when the result stays on the console's origin
 * under `/machines/<id>/` (`resolveWithin`, src/ui/safe-url.ts). `%2e%2e/other/…`, `/api/…`,
 * `//host`, `data:`, `blob:` and every other source is dropped with its `<img>`. (`data:` images
 * would be harmless as images, but Prunt never sends one: not needed, so not allowed.)
 * Links are kept only to external `https:` pages (`safeExternalHref`) and open in a new tab
 * without opener or referrer; any other link is unwrapped to its text.
 * Inline styles, `srcset`, `<base>`, `<meta>`, `<link>`, forms and every other attribute or element
 * are dropped (styles could cover the page); CSS keeps images within the panel.
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
  'base',
  'meta',
  'link',
  'form',
  'button',
  'input',
  'frame',
  'frameset',
  'applet',
  'picture',
  'source',
  'video',
  'audio',
  'portal',
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

/**
 * An image source from a description, resolved against the machine's prefix (`/machines/<id>`)
 * exactly as the browser resolves it; null unless it stays under `/machines/<id>/` on the
 * console's origin.
 */
export function resolveAsset(src: string, base: string): string | null {
  return resolveWithin(src, base);
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
          const h = safeExternalHref(v);
          if (h) n.setAttribute('href', h);
        } else n.setAttribute(a, v);
      }
      if (tag === 'img') {
        if (!n.getAttribute('src')) continue;
        if (!n.getAttribute('alt')) n.setAttribute('alt', 'Board documentation image');
      }
      if (tag === 'a') {
        if (!n.getAttribute('href')) {
          copy(el, to); // not a safe external link: keep its text only
          continue;
        }
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
