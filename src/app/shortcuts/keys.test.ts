// @vitest-environment happy-dom
import { afterEach, describe, expect, it } from 'vitest';
import { createKeyReader, isTypingTarget, pageBusy, SEQUENCE_MS, type KeyLike } from './keys';

const key = (k: string, more: Partial<KeyLike> = {}): KeyLike => ({
  key: k,
  ctrlKey: false,
  metaKey: false,
  altKey: false,
  target: document.body,
  ...more,
});

afterEach(() => {
  document.body.innerHTML = '';
});

describe('shortcut keys', () => {
  it('reads single keys and the two-key sequences', () => {
    let t = 0;
    const read = createKeyReader(() => t);
    expect(read(key('?'))).toBe('help');
    expect(read(key('j'))).toBe('next');
    expect(read(key(']'))).toBe('next');
    expect(read(key('k'))).toBe('previous');
    expect(read(key('['))).toBe('previous');
    expect(read(key('p'))).toBe('pause-resume');
    expect(read(key('g'))).toBeNull();
    t += 300;
    expect(read(key('f'))).toBe('go-fleet');
    expect(read(key('g'))).toBeNull();
    expect(read(key('a'))).toBe('go-alarms');
    // f and a alone are nothing; neither is an unknown key.
    expect(read(key('f'))).toBeNull();
    expect(read(key('a'))).toBeNull();
    expect(read(key('x'))).toBeNull();
  });

  it('forgets a g after the sequence time, or when another key comes between', () => {
    let t = 0;
    const read = createKeyReader(() => t);
    read(key('g'));
    t += SEQUENCE_MS + 1;
    expect(read(key('f'))).toBeNull();
    read(key('g'));
    expect(read(key('x'))).toBeNull();
    expect(read(key('f'))).toBeNull();
    // A key after g that is a shortcut of its own still works.
    read(key('g'));
    expect(read(key('j'))).toBe('next');
  });

  it('never fires with Ctrl, Alt or Meta, on a held key, or while composing', () => {
    const read = createKeyReader(() => 0);
    expect(read(key('p', { ctrlKey: true }))).toBeNull();
    expect(read(key('p', { metaKey: true }))).toBeNull();
    expect(read(key('j', { altKey: true }))).toBeNull();
    expect(read(key('p', { repeat: true }))).toBeNull();
    expect(read(key('p', { isComposing: true }))).toBeNull();
    expect(read(key('p', { defaultPrevented: true }))).toBeNull();
    // Ctrl+G then f is not `g f`.
    read(key('g', { ctrlKey: true }));
    expect(read(key('f'))).toBeNull();
  });

  it('never fires while typing in an input, a textarea, a select or editable text', () => {
    document.body.innerHTML = `
      <input id="i"><textarea id="t"></textarea><select id="s"><option>x</option></select>
      <div contenteditable="true"><span id="c">x</span></div>
      <div contenteditable="false"><span id="n">x</span></div>
      <button id="b">ok</button>`;
    const read = createKeyReader(() => 0);
    for (const id of ['i', 't', 's', 'c']) {
      const target = document.getElementById(id);
      expect(isTypingTarget(target)).toBe(true);
      expect(read(key('p', { target }))).toBeNull();
      expect(read(key('?', { target }))).toBeNull();
    }
    // A g typed into a field does not start a sequence either.
    read(key('g', { target: document.getElementById('i') }));
    expect(read(key('f'))).toBeNull();
    expect(isTypingTarget(document.getElementById('n'))).toBe(false);
    expect(read(key('p', { target: document.getElementById('b') }))).toBe('pause-resume');
  });

  it('knows when a dialog is open or the page is blocked', () => {
    expect(pageBusy(document)).toBe(false);
    document.body.innerHTML = '<dialog>closed</dialog><div data-testid="app-page"></div>';
    expect(pageBusy(document)).toBe(false);
    document.querySelector('dialog')?.setAttribute('open', '');
    expect(pageBusy(document)).toBe(true);
    document.querySelector('dialog')?.removeAttribute('open');
    document.querySelector('[data-testid="app-page"]')?.setAttribute('inert', '');
    expect(pageBusy(document)).toBe(true);
  });
});
