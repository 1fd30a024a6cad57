import { describe, expect, it } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { DuetClient, isAuthError, parseDuetError, quoteGcode } from './client';

describe('DuetClient helpers', () => {
  it('classifies DSF errors', () => {
    const e403 = parseDuetError(403, null, '');
    expect(e403?.status).toBe(403);
    expect(isAuthError(e403)).toBe(true);
    expect(isAuthError(new LinkError('http', 'x', { status: 401 }))).toBe(true);
    expect(parseDuetError(503, null, '')?.message).toMatch(/DCS is unavailable/);
    expect(parseDuetError(500, null, 'Directory 0:/gcodes/x is not empty')?.vendorMessage).toBe(
      'Directory 0:/gcodes/x is not empty',
    );
    expect(parseDuetError(409, null, 'exists')?.status).toBe(409);
    expect(parseDuetError(200, null, 'fine')).toBeNull();
  });
  it('puts the session key on the socket URL and encodes paths as one segment', () => {
    const c = new DuetClient('m1');
    c.sessionKey = 'k y';
    expect(c.socketUrl()).toBe('http://shopdeck.test/machines/m1/machine?sessionKey=k+y');
    expect(c.fileUrl('0:/gcodes/a b.gcode')).toBe(
      'http://shopdeck.test/machines/m1/machine/file/0%3A%2Fgcodes%2Fa%20b.gcode',
    );
    expect(quoteGcode('0:/gcodes/say "hi".gcode')).toBe('"0:/gcodes/say ""hi"".gcode"');
  });
});
