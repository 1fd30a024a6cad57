import { describe, expect, it } from 'vitest';
import {
  imageDataUrl,
  isImageDataUrl,
  MAX_DATA_URL_CHARS,
  pageOrigin,
  resolveWithin,
  safeExternalHref,
  safeImageBlob,
} from './safe-url';

const ORIGIN = 'http://host:8080';
/** As the sanitizer calls it in the browser: a path-only machine prefix on the page's origin. */
const img = (src: string) => resolveWithin(src, '/machines/p1', { origin: ORIGIN });

describe('resolveWithin: images from a machine stay on that machine', () => {
  it('keeps relative paths under the prefix, with their query, as the browser resolves them', () => {
    expect(img('extras/images/stepper_1.png')).toBe('/machines/p1/extras/images/stepper_1.png');
    expect(img('./extras/a.png')).toBe('/machines/p1/extras/a.png');
    expect(img('extras/a.png?v=2&size=large')).toBe('/machines/p1/extras/a.png?v=2&size=large');
    expect(img('extras/a.png#part')).toBe('/machines/p1/extras/a.png');
    expect(img('  extras/a.png ')).toBe('/machines/p1/extras/a.png');
    // `..` that stays inside the machine is the browser's business, and harmless.
    expect(img('extras/../b.png')).toBe('/machines/p1/b.png');
    expect(img('/machines/p1/extras/a.png')).toBe('/machines/p1/extras/a.png');
    expect(img('http://host:8080/machines/p1/extras/a.png')).toBe('/machines/p1/extras/a.png');
    expect(img('a b.png')).toBe('/machines/p1/a%20b.png');
  });

  it('drops the pen test: %2e%2e (either case, mixed with dots) leaves the machine', () => {
    expect(img('%2e%2e/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1')).toBeNull();
    expect(img('%2E%2E/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1')).toBeNull();
    expect(img('.%2e/g2/machine/panic')).toBeNull();
    expect(img('%2e./g2/machine/panic')).toBeNull();
    expect(img('extras/%2e%2e/%2e%2e/acc-laser/system?x=1')).toBeNull();
    expect(img('../acc-laser/system')).toBeNull();
    expect(img('../p1x/extras/a.png')).toBeNull(); // a machine whose id starts with "p1"
  });

  it('drops encoded slashes and backslashes that a decoding proxy would read as a way out', () => {
    expect(img('..%2facc-laser/system?action=x')).toBeNull();
    expect(img('..%2Facc-laser/system')).toBeNull();
    expect(img('%2f../acc-laser/system')).toBeNull();
    expect(img('..%5cacc-laser/system')).toBeNull();
    expect(img('extras/a%00.png')).toBeNull();
  });

  it('drops backslashes (the browser reads them as slashes)', () => {
    expect(img('..\\acc-laser/system')).toBeNull();
    expect(img('..\\..\\api\\users')).toBeNull();
    expect(img('\\\\evil.com/x.png')).toBeNull();
    expect(img('/\\evil.com/x.png')).toBeNull();
    expect(img('extras\\a.png')).toBeNull();
  });

  it('drops other hosts, other machines and the console API', () => {
    expect(img('//evil.com/x.png')).toBeNull();
    expect(img('https://evil.com/x.png')).toBeNull();
    expect(img('/machines/other/system?action=stop')).toBeNull();
    expect(img('http://host:8080/machines/other/')).toBeNull(); // absolute, same host
    expect(img('http://host:8080/machines/p1x/a.png')).toBeNull();
    expect(img('http://host:9090/machines/p1/a.png')).toBeNull(); // other port: other origin
    expect(img('https://host:8080/machines/p1/a.png')).toBeNull(); // other scheme: other origin
    expect(img('/api/users')).toBeNull();
    expect(img('/api/audit.csv')).toBeNull();
    // Prunt's own root is not the console's root: "/extras/…" would be the console's /extras/.
    expect(img('/extras/images/a.png')).toBeNull();
    expect(img('http://user:pw@host:8080/machines/p1/a.png')).toBeNull();
  });

  it('drops the prefix itself, query-only and empty sources (the controller root is no image)', () => {
    expect(img('')).toBeNull();
    expect(img('   ')).toBeNull();
    expect(img('.')).toBeNull();
    expect(img('?action=stop')).toBeNull();
    expect(img('/machines/p1/')).toBeNull();
    expect(img('/machines/p1')).toBeNull();
  });

  it('drops every non-http scheme, including blob: on our own origin', () => {
    expect(img('javascript:alert(1)')).toBeNull();
    expect(img('JaVaScRiPt:alert(1)')).toBeNull();
    expect(img('data:image/png;base64,iVBORw0KGgo=')).toBeNull();
    expect(img('data:image/svg+xml,<svg onload=alert(1)>')).toBeNull();
    expect(img('blob:http://host:8080/5f0c-4a')).toBeNull();
    expect(img('file:///etc/passwd')).toBeNull();
    expect(img('ftp://host:8080/machines/p1/a.png')).toBeNull();
  });

  it('drops control characters and whitespace inside the scheme', () => {
    expect(img('java\tscript:alert(1)')).toBeNull();
    expect(img('java\nscript:alert(1)')).toBeNull();
    expect(img('java\rscript:alert(1)')).toBeNull();
    expect(img('\u0000javascript:alert(1)')).toBeNull();
    expect(img('\u0001extras/a.png')).toBeNull();
    expect(img('%2e%2e\t/acc-laser/system')).toBeNull();
    expect(img('.\t./acc-laser/system')).toBeNull(); // the parser drops the tab: "../"
    expect(img('extras/\u007fa.png')).toBeNull();
  });

  it('keeps another id encoded as itself only: %70%31 is not p1', () => {
    expect(img('../%70%31/extras/a.png')).toBeNull();
  });

  it('answers in the form of the base: absolute for an absolute base (Node tests, api origin)', () => {
    const base = 'http://shopdeck.test/machines/p1';
    expect(resolveWithin('extras/a.png', base, { origin: null })).toBe(
      'http://shopdeck.test/machines/p1/extras/a.png',
    );
    expect(resolveWithin('%2e%2e/acc-laser/system', base, { origin: null })).toBeNull();
    expect(resolveWithin('http://shopdeck.test/api/users', base, { origin: null })).toBeNull();
  });

  it('without a page origin, a path-only base only accepts relative sources', () => {
    expect(resolveWithin('extras/a.png', '/machines/p1', { origin: null })).toBe('/machines/p1/extras/a.png');
    expect(resolveWithin('http://host:8080/machines/p1/a.png', '/machines/p1', { origin: null })).toBeNull();
    expect(resolveWithin('%2e%2e/acc-laser/x', '/machines/p1', { origin: null })).toBeNull();
  });

  it('keeps a folder below the machine: downloads stay in /uploads/', () => {
    const up = (name: string) => resolveWithin(name, '/machines/p1/uploads/', { origin: ORIGIN });
    expect(up('benchy.gcode')).toBe('/machines/p1/uploads/benchy.gcode');
    expect(up('..')).toBeNull();
    expect(up('../config/values')).toBeNull();
    expect(up('%2e%2e')).toBeNull();
    expect(up('%252e%252e')).toBe('/machines/p1/uploads/%252e%252e'); // a file called "%2e%2e"
  });

  it('refuses a base that is not a plain folder (it would widen the scope)', () => {
    expect(resolveWithin('a.png', '', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('a.png', '/', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('api/users', '/machines/..', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('api/users', '/machines/%2e%2e', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('x', '/machines/a%2Fb', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('a.png', '//evil.com/machines/p1', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('a.png', 'machines/p1', { origin: ORIGIN })).toBeNull();
    expect(resolveWithin('a.png', 'javascript:alert(1)//', { origin: ORIGIN })).toBeNull();
  });
});

describe('safeExternalHref: links lead only to external https pages', () => {
  const link = (h: string) => safeExternalHref(h, ORIGIN);

  it('keeps external https links (normalised)', () => {
    expect(link('https://github.com/Prunt3D/prunt/releases')).toBe(
      'https://github.com/Prunt3D/prunt/releases',
    );
    expect(link(' https://example.com/a?b=1#c ')).toBe('https://example.com/a?b=1#c');
    expect(link('HTTPS://Example.COM')).toBe('https://example.com/');
  });

  it('drops http:, javascript:, data:, blob:, mailto:, file: and control characters in the scheme', () => {
    expect(link('http://github.com/x')).toBeNull();
    expect(link('javascript:alert(1)')).toBeNull();
    expect(link('java\tscript:alert(1)')).toBeNull();
    expect(link('\u0000javascript:alert(1)')).toBeNull();
    expect(link('data:text/html,<script>alert(1)</script>')).toBeNull();
    expect(link('blob:https://example.com/5f0c')).toBeNull();
    expect(link('mailto:a@example.com')).toBeNull();
    expect(link('file:///etc/passwd')).toBeNull();
    expect(link('ht\ntps://example.com')).toBeNull();
  });

  it('drops relative links and links back into the console (machines, API), whatever the port', () => {
    expect(link('/machines/p2/system?action=stop')).toBeNull();
    expect(link('%2e%2e/acc-laser/system')).toBeNull();
    expect(link('//evil.com/x')).toBeNull(); // scheme-relative: not an absolute https URL
    expect(link('https://host:8080/machines/p2/x')).toBeNull();
    expect(link('https://host/api/users')).toBeNull();
    expect(link('https://HOST:9999/')).toBeNull();
  });

  it('drops links to the console host by its public name, on any port or scheme', () => {
    const own = (h: string) => safeExternalHref(h, 'https://shopdeck.example.com');
    expect(own('https://shopdeck.example.com/machines/p2/system?action=stop')).toBeNull();
    expect(own('https://SHOPDECK.example.com:9443/')).toBeNull();
    expect(own('https://other.example.com/')).toBe('https://other.example.com/');
  });

  it('drops backslash tricks, credentials, IP addresses and local names', () => {
    expect(link('https:\\\\evil.com')).toBeNull();
    expect(link('https://example.com\\@host:8080/')).toBeNull();
    expect(link('https://user:pw@example.com/')).toBeNull();
    expect(link('https://example.com@evil.com/')).toBeNull();
    expect(link('https://192.168.1.50/system?action=stop')).toBeNull();
    expect(link('https://2130706433/')).toBeNull(); // 127.0.0.1
    expect(link('https://0x7f.1/')).toBeNull();
    expect(link('https://[::1]/')).toBeNull();
    expect(link('https://localhost/')).toBeNull();
    expect(link('https://prunt/')).toBeNull();
    expect(link('https://laser.local/')).toBeNull();
    expect(link('https://g2.lan/')).toBeNull();
    expect(link('https://example.com./')).toBeNull();
  });

  it('without a page origin still requires an external https name', () => {
    expect(safeExternalHref('https://example.com/', null)).toBe('https://example.com/');
    expect(safeExternalHref('http://example.com/', null)).toBeNull();
    expect(safeExternalHref('/machines/p2/x', null)).toBeNull();
  });
});

describe('image data URLs', () => {
  it('builds data URLs of raster types with base64 data only', () => {
    expect(imageDataUrl('image/png', 'iVBORw0KGgo=')).toBe('data:image/png;base64,iVBORw0KGgo=');
    expect(imageDataUrl('image/jpeg', '/9j/\n4AAQ')).toBe('data:image/jpeg;base64,/9j/4AAQ');
    expect(imageDataUrl('image/webp', 'UklGRg==')).toBe('data:image/webp;base64,UklGRg==');
    expect(imageDataUrl('image/gif', 'R0lGODlh')).toBe('data:image/gif;base64,R0lGODlh');
  });

  it('refuses SVG, HTML and other types, and data that would break out of the URL', () => {
    expect(imageDataUrl('image/svg+xml', 'PHN2Zz4=')).toBeNull();
    expect(imageDataUrl('text/html', 'PHNjcmlwdD4=')).toBeNull();
    expect(imageDataUrl('image/png;charset=x', 'AAAA')).toBeNull();
    expect(imageDataUrl('image/png', '')).toBeNull();
    expect(imageDataUrl('image/png', 'AAAA,<svg onload=alert(1)>')).toBeNull();
    expect(imageDataUrl('image/png', 'AAAA" onerror="alert(1)')).toBeNull();
    expect(imageDataUrl('image/png', 'AAAA#x')).toBeNull();
    expect(imageDataUrl('image/png', 'AAAAA')).toBeNull(); // not a base64 length
    expect(imageDataUrl('image/png', 'A'.repeat(MAX_DATA_URL_CHARS + 4))).toBeNull();
  });

  it('recognises only what imageDataUrl makes', () => {
    expect(isImageDataUrl('data:image/png;base64,iVBORw0KGgo=')).toBe(true);
    expect(isImageDataUrl('data:image/svg+xml;base64,PHN2Zz4=')).toBe(false);
    expect(isImageDataUrl('data:text/html;base64,PHNjcmlwdD4=')).toBe(false);
    expect(isImageDataUrl('data:image/png,<svg>')).toBe(false);
    expect(isImageDataUrl('data:image/png;base64,AAAA\nAAAA')).toBe(false);
    expect(isImageDataUrl('javascript:alert(1)')).toBe(false);
    expect(isImageDataUrl('/machines/p1/a.png')).toBe(false);
  });
});

describe('safeImageBlob', () => {
  it('keeps raster image blobs and drops HTML, SVG and untyped blobs', () => {
    const png = new Blob(['x'], { type: 'image/png' });
    expect(safeImageBlob(png)).toBe(png);
    const jpeg = new Blob(['x'], { type: 'image/jpeg' });
    expect(safeImageBlob(jpeg)).toBe(jpeg);
    expect(safeImageBlob(new Blob(['<script>alert(1)</script>'], { type: 'text/html' }))).toBeNull();
    expect(safeImageBlob(new Blob(['<svg onload=alert(1)>'], { type: 'image/svg+xml' }))).toBeNull();
    expect(safeImageBlob(new Blob(['x']))).toBeNull();
    expect(safeImageBlob(null)).toBeNull();
  });
});

describe('pageOrigin', () => {
  it('is null without an http(s) page (Node)', () => {
    expect(pageOrigin()).toBeNull();
  });
});
