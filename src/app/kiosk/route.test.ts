import { describe, expect, it } from 'vitest';
import { matchRoute } from '../router';

describe('the kiosk flag', () => {
  it('marks a machine route given `?kiosk`, with or without a value or a section', () => {
    expect(matchRoute('/m/laser-1', '?kiosk')).toEqual({
      name: 'machine',
      id: 'laser-1',
      tab: null,
      kiosk: true,
    });
    expect(matchRoute('/m/laser-1', '?kiosk=1')).toMatchObject({ kiosk: true });
    expect(matchRoute('/m/laser-1/files', '?x=1&kiosk')).toMatchObject({
      id: 'laser-1',
      tab: 'files',
      kiosk: true,
    });
  });

  it('is absent without the flag, and means nothing on other pages', () => {
    expect(matchRoute('/m/laser-1', '')).not.toHaveProperty('kiosk');
    expect(matchRoute('/m/laser-1', '?kiosky')).not.toHaveProperty('kiosk');
    expect(matchRoute('/m/laser-1')).not.toHaveProperty('kiosk');
    expect(matchRoute('/audit', '?kiosk')).toEqual({ name: 'audit' });
    expect(matchRoute('/', '?kiosk')).toEqual({ name: 'fleet' });
  });
});
