// @vitest-environment happy-dom
import { beforeAll, describe, expect, it } from 'vitest';
import { resolveAsset, sanitizeHtml } from './sanitize';

interface HappyDomSettings {
  disableCSSFileLoading: boolean;
  disableIframePageLoading: boolean;
  handleDisabledFileLoadingAsSuccess: boolean;
  navigation: { disableMainFrameNavigation: boolean; disableChildFrameNavigation: boolean };
}

beforeAll(() => {
  // happy-dom's DOMParser is not inert as a browser's is: it would fetch the attack's stylesheets
  // from a server that is not there. Browsers load nothing from a DOMParser document.
  const s = (window as unknown as { happyDOM?: { settings: HappyDomSettings } }).happyDOM?.settings;
  if (!s) return;
  s.disableCSSFileLoading = true;
  s.disableIframePageLoading = true;
  s.handleDisabledFileLoadingAsSuccess = true;
  s.navigation.disableMainFrameNavigation = true;
  s.navigation.disableChildFrameNavigation = true;
});

/** The page's origin under happy-dom (vitest's default URL). */
const HOST = 'http://localhost:3000';

function parse(out: string): HTMLDivElement {
  const div = document.createElement('div');
  div.innerHTML = out;
  return div;
}

/** The src of every image that survives, for a description made of one image. */
function imageSources(src: string, tag = 'img'): string[] {
  const out = sanitizeHtml(`<p>Pinout:<${tag} src="${src}"></p>`, '/machines/p1');
  return [...parse(out).querySelectorAll('img')].map((i) => i.getAttribute('src') ?? '');
}

describe('sanitizeHtml', () => {
  it('keeps paragraphs, line breaks and the board pinout image (through the machine prefix)', () => {
    const html =
      '<p>Note that the pinout.</p><p><br>Board-specific documentation:</p><p><image src="extras/images/stepper_1.png" style="max-width: 600px; width:100%;"></p>';
    const div = parse(sanitizeHtml(html, '/machines/p1'));
    expect(div.querySelectorAll('p').length).toBe(3);
    expect(div.querySelector('br')).not.toBeNull();
    const img = div.querySelector('img');
    expect(img?.getAttribute('src')).toBe('/machines/p1/extras/images/stepper_1.png');
    expect(img?.getAttribute('style')).toBeNull();
  });

  it('removes scripts, handlers, javascript: links and foreign images', () => {
    const out = sanitizeHtml(
      '<p onclick="x()">a<script>alert(1)</script><a href="javascript:alert(1)">l</a><img src="https://evil.example/x.png" onerror="y()"><iframe src="/"></iframe></p>',
      '/machines/p1',
    );
    expect(out).not.toMatch(/script|onclick|onerror|javascript:|iframe|evil\.example/);
    expect(out).toContain('<p>a');
  });

  it('resolves image sources as the browser does and keeps them only under the machine prefix', () => {
    expect(resolveAsset('extras/a.png', '/machines/x')).toBe('/machines/x/extras/a.png');
    expect(resolveAsset('./extras/a.png', '/machines/x/')).toBe('/machines/x/extras/a.png');
    // Root-absolute is the console's root, not the controller's: outside the prefix.
    expect(resolveAsset('/extras/a.png', '/machines/x/')).toBeNull();
    expect(resolveAsset('data:image/png;base64,AA', '/m')).toBeNull();
    expect(resolveAsset('//evil/a.png', '/m')).toBeNull();
    expect(resolveAsset('../../api/secret', '/m')).toBeNull();
  });
});

describe('sanitizeHtml: controller images never reach another machine or the API', () => {
  it('drops the pen test payload (%2e%2e to the laser flame alarm) with its <img>', () => {
    const out = sanitizeHtml(
      '<p>Help</p><img src="%2e%2e/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1">',
      '/machines/p1',
    );
    expect(parse(out).querySelector('img')).toBeNull();
    expect(out).not.toMatch(/acc-laser|setFlameAlarmMode|%2e/i);
    expect(out).toContain('<p>Help</p>');
  });

  it.each([
    ['%2e%2e/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1'],
    ['%2E%2E/acc-laser/system?action=stop'],
    ['.%2e/g2/machine/panic'],
    ['extras/%2e%2e/%2e%2e/g2/machine/panic'],
    ['../acc-laser/system'],
    ['..%2facc-laser/system?action=stop'],
    ['%2f../acc-laser/system'],
    ['..\\acc-laser/system'],
    ['..\\..\\api\\users'],
    ['\\\\evil.com/x.png'],
    ['//evil.com/x.png'],
    ['https://evil.com/x.png'],
    ['/machines/other/system?action=stop'],
    ['../p1x/x.png'],
    ['/api/users'],
    ['/api/audit.csv'],
    [`${HOST}/machines/other/`],
    [`${HOST}/api/users`],
    ['javascript:alert(1)'],
    ['java\tscript:alert(1)'],
    ['java&#9;script:alert(1)'],
    ['java&#x0A;script:alert(1)'],
    ['&#x01;javascript:alert(1)'],
    ['data:image/png;base64,iVBORw0KGgo='],
    ['data:image/svg+xml,&lt;svg onload=alert(1)&gt;'],
    [`blob:${HOST}/5f0c-4a`],
    ['%2e%2e&#9;/acc-laser/system'],
    ['?action=stop'],
    ['.'],
    [''],
  ])('drops <img src="%s"> and <image src=…>', (src) => {
    expect(imageSources(src)).toEqual([]);
    expect(imageSources(src, 'image')).toEqual([]);
  });

  it('keeps same-machine sources with a query, relative or absolute on the same origin', () => {
    expect(imageSources('extras/images/a.png?v=2&amp;s=1')).toEqual([
      '/machines/p1/extras/images/a.png?v=2&s=1',
    ]);
    expect(imageSources(`${HOST}/machines/p1/extras/a.png`)).toEqual(['/machines/p1/extras/a.png']);
    expect(imageSources('/machines/p1/extras/a.png')).toEqual(['/machines/p1/extras/a.png']);
  });

  it('drops srcset (the browser would load it instead of src)', () => {
    const out = sanitizeHtml(
      '<img src="extras/a.png" srcset="%2e%2e/acc-laser/system?action=stop 1x, //evil.com/x 2x"><picture><source srcset="/api/users"><img src="extras/b.png"></picture>',
      '/machines/p1',
    );
    expect(out).not.toMatch(/srcset|acc-laser|evil|api|<source|<picture/);
    expect([...parse(out).querySelectorAll('img')].map((i) => i.getAttribute('src'))).toEqual([
      '/machines/p1/extras/a.png',
    ]);
  });
});

describe('sanitizeHtml: links lead only to external https pages', () => {
  it('keeps an external https link, opened without opener or referrer', () => {
    const a = parse(
      sanitizeHtml(
        '<p>See <a href="https://prunt3d.com/docs" target="_self" rel="opener">the docs</a></p>',
        '/m/p1',
      ),
    ).querySelector('a');
    expect(a?.getAttribute('href')).toBe('https://prunt3d.com/docs');
    expect(a?.getAttribute('target')).toBe('_blank');
    expect(a?.getAttribute('rel')).toBe('noopener noreferrer');
    expect(a?.textContent).toBe('the docs');
  });

  it.each([
    ['%2e%2e/acc-laser/system?action=stop'],
    ['../acc-laser/system'],
    ['/machines/other/machine/panic'],
    ['/api/users'],
    [`${HOST}/machines/p2/`],
    ['https://localhost:3000/api/users'],
    ['https://localhost:4000/'],
    ['http://prunt3d.com/'],
    ['javascript:alert(1)'],
    ['java&#9;script:alert(1)'],
    ['JAVASCRIPT:alert(1)'],
    ['data:text/html,&lt;script&gt;alert(1)&lt;/script&gt;'],
    [`blob:${HOST}/5f0c`],
    ['mailto:a@example.com'],
    ['//evil.com/'],
    ['https:\\\\evil.com'],
    ['https://192.168.1.50/system?action=stop'],
    ['vbscript:x'],
    [''],
  ])('unwraps <a href="%s"> to its text', (href) => {
    const out = sanitizeHtml(`<p>Go <a href="${href}" target="_self">there</a> now</p>`, '/machines/p1');
    const div = parse(out);
    expect(div.querySelector('a')).toBeNull();
    expect(div.textContent).toBe('Go there now');
  });

  it('unwraps a link without href, and drops formaction and xlink:href', () => {
    const out = sanitizeHtml(
      '<a name="x">named</a><form action="/machines/g2/machine/panic"><button formaction="/machines/g2/machine/panic">Go</button><input type="submit" formaction="/api/x"></form><a xlink:href="javascript:alert(1)">x</a>',
      '/machines/p1',
    );
    const div = parse(out);
    expect(div.querySelector('a, form, button, input')).toBeNull();
    expect(out).not.toMatch(/formaction|xlink|action=|panic|javascript/i);
    expect(div.textContent).toContain('named');
  });
});

describe('sanitizeHtml: nothing that navigates or loads survives', () => {
  it('drops <base>, <meta http-equiv=refresh>, <link>, style and SVG links', () => {
    const out = sanitizeHtml(
      [
        '<base href="/machines/acc-laser/">',
        '<meta http-equiv="refresh" content="0;url=/machines/g2/machine/panic">',
        '<link rel="stylesheet" href="/machines/acc-laser/system?action=stop">',
        '<link rel="prefetch" href="/api/users">',
        '<style>@import "/machines/acc-laser/system?action=stop";</style>',
        '<p style="background:url(/machines/acc-laser/system?action=stop)">text</p>',
        '<svg><a xlink:href="javascript:alert(1)"><text>svg</text></a><image href="/api/users"/></svg>',
        '<video poster="/api/users" src="/api/x"></video><audio src="/api/y"></audio>',
        '<object data="/api/users"></object><embed src="/api/users">',
        '<iframe srcdoc="&lt;script&gt;alert(1)&lt;/script&gt;"></iframe>',
      ].join(''),
      '/machines/p1',
    );
    expect(out).toBe('<p>text</p>');
  });

  it('keeps only src, alt, href and title: no handler, style, srcset or data attribute on kept tags', () => {
    const out = sanitizeHtml(
      '<img src="extras/a.png" alt="pin" title="t" srcset="/api/x 2x" style="position:fixed" onerror="x()" loading="eager" data-x="1" width="9999">',
      '/machines/p1',
    );
    const img = parse(out).querySelector('img');
    expect(img?.getAttributeNames().sort()).toEqual(['alt', 'src', 'title']);
  });

  it('escapes, never passes through, when there is no DOM', async () => {
    // Covered in Node by the escaping branch: markup becomes text.
    const { escapeHtml } = await import('./sanitize');
    expect(escapeHtml('<img src=x>')).toBe('&#60;img src=x&#62;');
  });
});
