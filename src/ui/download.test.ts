// @vitest-environment happy-dom
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { downloadCsv, downloadFile } from './download';

describe('downloadFile', () => {
  const created: Blob[] = [];
  const revoked: string[] = [];
  const clicked: Array<{ href: string; download: string; inDocument: boolean }> = [];

  beforeEach(() => {
    vi.useFakeTimers();
    created.length = 0;
    revoked.length = 0;
    clicked.length = 0;
    vi.spyOn(URL, 'createObjectURL').mockImplementation((b) => {
      created.push(b as Blob);
      return `blob:test/${created.length}`;
    });
    vi.spyOn(URL, 'revokeObjectURL').mockImplementation((u) => void revoked.push(u));
    vi.spyOn(HTMLAnchorElement.prototype, 'click').mockImplementation(function (this: HTMLAnchorElement) {
      clicked.push({ href: this.href, download: this.download, inDocument: document.body.contains(this) });
    });
  });
  afterEach(() => {
    vi.restoreAllMocks();
    vi.useRealTimers();
  });

  it('clicks a temporary <a download> on an object URL and revokes the URL afterwards', async () => {
    downloadFile('log.txt', 'hello', 'text/plain');
    expect(clicked).toEqual([{ href: 'blob:test/1', download: 'log.txt', inDocument: true }]);
    expect(await created[0]!.text()).toBe('hello');
    expect(created[0]!.type).toBe('text/plain');
    // The link is gone, the URL not yet revoked (the browser may still read it)…
    expect(document.querySelectorAll('a').length).toBe(0);
    expect(revoked).toEqual([]);
    // …until later.
    vi.advanceTimersByTime(10_000);
    expect(revoked).toEqual(['blob:test/1']);
  });

  it('passes a Blob through as it is', () => {
    const blob = new Blob([new Uint8Array([1, 2, 3])], { type: 'image/png' });
    downloadFile('a.png', blob);
    expect(created[0]).toBe(blob);
  });

  it('revokes the URL even when the click throws', () => {
    vi.mocked(HTMLAnchorElement.prototype.click).mockImplementation(() => {
      throw new Error('blocked');
    });
    expect(() => downloadFile('x.txt', 'x')).toThrow('blocked');
    vi.advanceTimersByTime(10_000);
    expect(revoked).toEqual(['blob:test/1']);
    expect(document.querySelectorAll('a').length).toBe(0);
  });

  it('downloadCsv sends CSV as UTF-8 text/csv', async () => {
    downloadCsv('t.csv', 'a\r\n');
    expect(created[0]!.type).toBe('text/csv;charset=utf-8');
    expect(await created[0]!.text()).toBe('a\r\n');
    expect(clicked[0]!.download).toBe('t.csv');
  });
});
