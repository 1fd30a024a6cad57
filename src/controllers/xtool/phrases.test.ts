import { describe, expect, it } from 'vitest';
import { frameTerm, frameWords } from './phrases';

describe('xTool phrases: socket frames in words', () => {
  it('says each known frame in words, an unknown one as unknown, and keeps the term without its prefix', () => {
    expect(frameWords('ok:WORKING_ONLINE')).toBe('working on a job sent from a computer');
    expect(frameWords('err:flameCheck')).toBe('flame detected');
    expect(frameWords('ok:SOMETHING_NEW')).toBe('a message this console does not know');
    expect(frameTerm('ok:WORKING_ONLINE')).toBe('WORKING_ONLINE');
    expect(frameTerm(`ok:${'X'.repeat(100)}`)).toHaveLength(40);
  });
});
