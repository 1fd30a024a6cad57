// @vitest-environment happy-dom
import { cleanup, render } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { thumbnailSchema } from '../wire';
import { Thumbnail, thumbnailSrc } from './common';

afterEach(() => cleanup());

/** The thumbnail as the controller would send it, through the wire schema. */
function thumb(format: unknown, data: unknown) {
  return thumbnailSchema.parse({ format, width: 48, height: 48, offset: 0, size: 10, data });
}

function renderedSrc(format: unknown, data: unknown): string | null {
  const { container } = render(<Thumbnail thumb={thumb(format, data)} />);
  const src = container.querySelector('img')?.getAttribute('src') ?? null;
  cleanup();
  return src;
}

describe('Duet thumbnails', () => {
  it('show PNG and JPEG base64 data as data URLs of their type', () => {
    expect(renderedSrc('png', 'iVBORw0KGgo=')).toBe('data:image/png;base64,iVBORw0KGgo=');
    expect(renderedSrc('jpeg', '/9j/4AAQ')).toBe('data:image/jpeg;base64,/9j/4AAQ');
  });

  it.each([
    ['png', 'AAAA,<svg onload=alert(1)>'],
    ['png', 'AAAA" onerror="alert(1)'],
    ['png', 'x;base64,PHNjcmlwdD4='],
    ['jpeg', '#<script>'],
    ['png', ''],
    ['svg', 'PHN2ZyBvbmxvYWQ9YWxlcnQoMSk+'],
    ['svg+xml', 'PHN2Zz4='],
    ['html', 'PHNjcmlwdD5hbGVydCgxKTwvc2NyaXB0Pg=='],
    ['image/svg+xml', 'PHN2Zz4='],
    ['png;base64,AAAA#', 'AAAA'],
    ['__proto__', 'AAAA'],
    ['toString', 'AAAA'],
  ])('never turn format %j with data %j into an image URL', (format, data) => {
    expect(renderedSrc(format, data)).toBeNull();
    expect(thumbnailSrc(String(thumb(format, data).format), data)).toBeNull();
  });

  it('only ever produce a data:image/(png|jpeg);base64 URL', () => {
    for (const f of ['png', 'jpeg', 'qoi', 'svg', 'gif', 'x']) {
      for (const d of ['iVBORw0KGgo=', 'a b', '<svg/>', 'javascript:alert(1)']) {
        const src = thumbnailSrc(f, d);
        if (src !== null) expect(src).toMatch(/^data:image\/(png|jpeg);base64,[A-Za-z0-9+/]+={0,2}$/);
      }
    }
  });
});
