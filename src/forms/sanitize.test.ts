// @vitest-environment happy-dom
import { describe, expect, it } from 'vitest';
import { resolveAsset, sanitizeHtml } from './sanitize';

describe('sanitizeHtml', () => {
  it('keeps paragraphs, line breaks and the board pinout image (through the machine prefix)', () => {
    const html =
      '<p>Note that the pinout.</p><p><br>Board-specific documentation:</p><p><image src="extras/images/stepper_1.png" style="max-width: 600px; width:100%;"></p>';
    const out = sanitizeHtml(html, '/machines/p1');
    const div = document.createElement('div');
    div.innerHTML = out;
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

  it('resolves only relative asset paths', () => {
    expect(resolveAsset('extras/a.png', '/machines/x')).toBe('/machines/x/extras/a.png');
    expect(resolveAsset('/extras/a.png', '/machines/x/')).toBe('/machines/x/extras/a.png');
    expect(resolveAsset('data:image/png;base64,AA', '/m')).toBeNull();
    expect(resolveAsset('//evil/a.png', '/m')).toBeNull();
    expect(resolveAsset('../../api/secret', '/m')).toBeNull();
  });
});
