import { describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { roleAtLeast } from '../../fleet/types';
import { classifyCode } from './access';
import { DuetSession } from './session';

/** Every G-code command's body is allowed, by the gateway's policy, to the role the command declares. */
describe('command roles match the access policy', () => {
  it('for every command that sends G-code', async () => {
    const ctx = createContext(
      { id: 'dr', name: 'D', kind: 'duet', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 's', role: 'supervisor' }) },
    );
    const session = new DuetSession(ctx);
    const sent: string[] = [];
    vi.spyOn(session.client, 'code').mockImplementation(async (code: string) => {
      sent.push(code);
      return '';
    });
    const box = {
      mode: 5,
      seq: 3,
      axisControls: 0,
      cancelButton: true,
      choices: null,
      default: 1,
      max: 9,
      min: 0,
      message: '',
      timeout: 0,
      title: '',
    };
    const c = session.cmd;
    const cases: Array<[{ role: 'viewer' | 'operator' | 'supervisor'; id: string }, () => Promise<unknown>]> =
      [
        [c.start, () => c.start.perform({ path: '0:/gcodes/a "b".gcode' }, { commandId: c.start.id })],
        [c.simulate, () => c.simulate.perform({ path: '0:/gcodes/a.gcode' }, { commandId: c.simulate.id })],
        [c.pause, () => c.pause.perform(undefined, { commandId: c.pause.id })],
        [c.resume, () => c.resume.perform(undefined, { commandId: c.resume.id })],
        [c.cancel, () => c.cancel.perform(undefined, { commandId: c.cancel.id })],
        [c.estop, () => c.estop.perform(undefined, { commandId: c.estop.id })],
        [c.answer, () => c.answer.perform({ box, value: 4 }, { commandId: c.answer.id })],
        [c.answer, () => c.answer.perform({ box, cancel: true }, { commandId: c.answer.id })],
        [c.heaterReset, () => c.heaterReset.perform({ heater: 1 }, { commandId: c.heaterReset.id })],
        [c.macro, () => c.macro.perform({ path: '0:/macros/x.g' }, { commandId: c.macro.id })],
      ];
    for (const [cmd, run] of cases) {
      sent.length = 0;
      await run();
      expect(sent, cmd.id).toHaveLength(1);
      const decision = classifyCode(sent[0]!);
      // The gateway must let the declared role through, and not let less through than the UI shows.
      expect(roleAtLeast(cmd.role, decision.role), `${cmd.id}: ${sent[0]} needs ${decision.role}`).toBe(true);
      expect(decision.role, `${cmd.id}: ${sent[0]}`).toBe(cmd.role);
    }
  });
});
