import type { CommandContext } from '../../fleet/commands';
import { LinkError, describeError } from '../../fleet/errors';
import { defineCommands } from '../../fleet/kernel';
import type { SwitchAction } from './client';
import type { UploadState } from './model';
import { FILES_KEY, SETTINGS_KEY } from './queries';
import { applyJobAction, isRunningJob } from './state';
import { verifiedUpload, type UploadArgs, type UploadHost } from './upload';
import { flameSensitivityWords } from './wire';

/**
 * Every command of an xTool D-series laser, declared once with `defineCommands`: availability
 * reads only the machine snapshot and the family's `detail` store (so a button follows both).
 * The ids are in the audit log and in `access.ts`: never rename one.
 */

/** What the commands need of the session. */
export interface CommandHost extends UploadHost {
  /** Poll the status now, or right after the poll in flight. */
  kick(): void;
}

type Sensor = 'limit' | 'tilt' | 'moving';
const SWITCH: Record<Sensor, { action: SwitchAction; words: string; risk: string }> = {
  limit: {
    action: 'setLimitStopSwitch',
    words: 'limit stop',
    risk: 'the laser head can drive into the frame ends without stopping the job',
  },
  tilt: {
    action: 'setTiltStopSwitch',
    words: 'tilt stop',
    risk: 'the laser keeps firing when the machine tips over or is lifted',
  },
  moving: {
    action: 'setMovingStopSwitch',
    words: 'movement stop',
    risk: 'the laser keeps firing when the machine is bumped or moved',
  },
};

type ByteAction = 'setTiltCheckThreshold' | 'setMovingCheckThreshold' | 'setFlameAlarmMode';

function checkByte(value: number, what: string): void {
  if (!Number.isInteger(value) || value < 0 || value > 255) {
    throw new LinkError('vendor', `${what} must be a whole number from 0 to 255 (got ${value})`);
  }
}

export function xtoolCommands(host: CommandHost) {
  const { client, detail } = host;
  const cmds = defineCommands({ snapshot: host.ctx.snapshot, xtool: detail });

  /**
   * pause, resume, stop: the laser answers "fail" when the action is not possible (document), so
   * its "ok" is its own word and the state follows at once; a poll right after confirms it.
   */
  const jobAction =
    (action: 'pause' | 'resume' | 'stop', done: string) =>
    async (_a: void, { commandId }: CommandContext) => {
      const run = host.run();
      await client.jobAction(action, commandId);
      if (run.alive()) {
        detail.setState((s) => ({ machine: applyJobAction(s.machine, action), source: 'command' }));
        host.publish();
        host.kick();
      }
      return done;
    };

  const pause = cmds.define({
    id: 'xtool.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: ({ xtool }) =>
      xtool.machine.state === 'running' || xtool.machine.state === 'button' ? true : 'No job is running',
    perform: jobAction('pause', 'job paused'),
  });

  const resume = cmds.define({
    id: 'xtool.resume',
    label: 'Resume',
    hazard: 'job',
    role: 'operator',
    confirm: 'Resume the job? The laser fires again.',
    available: ({ xtool }) => (xtool.machine.state === 'paused' ? true : 'The job is not paused'),
    perform: jobAction('resume', 'job resumed'),
  });

  const stopJob = cmds.define({
    id: 'xtool.stop',
    label: 'Stop',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Stop the job? It cannot be resumed; the piece may be spoiled.',
    available: ({ xtool }) => {
      const s = xtool.machine.state;
      return isRunningJob(s) || s === 'job-loaded' || s === 'frame-ready' ? true : 'Nothing to stop';
    },
    perform: jobAction('stop', 'job stopped'),
  });

  const upload = cmds.define<UploadArgs>({
    id: 'xtool.upload',
    label: 'Upload',
    hazard: 'job',
    role: 'operator',
    confirm: (a) =>
      a.target.kind === 'path'
        ? `Copy ${a.name} to ${a.target.filename} on the SD card?`
        : `Upload ${a.name} as the ${a.target.kind === 'frame' ? 'framing file' : 'job'}? The laser then waits: it starts with the button on the machine.`,
    available: ({ xtool }) => {
      if (isRunningJob(xtool.machine.state)) return 'The laser is busy with a job';
      if (xtool.periphery?.sdCard === false) return 'No SD card in the laser';
      return true;
    },
    // No `invalidates`: the upload's own verification listing is the folder's new listing.
    perform: async (a, { commandId }) => {
      const message = await verifiedUpload(host, a, commandId);
      host.kick();
      return message;
    },
  });

  const deleteFile = cmds.define<{ path: string }>({
    id: 'xtool.delete',
    label: 'Delete file',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: (a) => `Delete ${a.path} from the laser's SD card? This cannot be undone.`,
    invalidates: [FILES_KEY],
    perform: async (a, { commandId }) => {
      await client.deleteFile(a.path, commandId);
      return `deleted ${a.path}`;
    },
  });

  const runFile = cmds.define<{ path: string }>({
    id: 'xtool.run-file',
    label: 'Run file now (remote start)',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm: (a) =>
      `Run ${a.path} now? This FIRES THE LASER immediately, without anyone at the machine pressing its button. ` +
      'Send it only if someone is at the laser and watching it.',
    available: ({ xtool }) => {
      const s = xtool.machine.state;
      return s === 'idle' || s === 'job-loaded' || s === 'frame-ready' ? true : 'The laser is busy';
    },
    perform: async (a, { commandId }) => {
      const run = host.run();
      await client.runFile(a.path, commandId);
      if (run.alive()) {
        detail.setState({ jobName: a.path.slice(a.path.lastIndexOf('/') + 1), notice: null });
        host.publish();
        host.kick();
      }
      return `started ${a.path}`;
    },
  });

  const gcode = cmds.define<{ code: string }>({
    id: 'xtool.gcode',
    label: 'Send G-code',
    hazard: 'motion',
    role: 'supervisor',
    // Decision: the console is a supervisor tool used line by line; no confirmation per line.
    confirm: false,
    perform: async (a, { commandId }) => {
      const code = a.code.trim();
      if (!code) throw new LinkError('vendor', 'Nothing to send');
      const run = host.run();
      const entry = (ok: boolean, reply: string) => {
        if (!run.alive()) return;
        const at = host.ctx.now();
        detail.setState((s) => ({ console: [...s.console, { at, code, ok, reply }].slice(-200) }));
      };
      try {
        const r = await client.gcode(code, commandId);
        entry(true, r.result);
        if (run.alive()) host.ctx.log.info('console', `> ${code.replace(/\n/g, ' | ')} → ${r.result}`);
        return r.result;
      } catch (e) {
        entry(false, describeError(e));
        throw e;
      }
    },
  });

  const setName = cmds.define<{ name: string }>({
    id: 'xtool.set-name',
    label: 'Rename the laser',
    hazard: 'adjust',
    role: 'supervisor',
    perform: async (a, { commandId }) => {
      const name = a.name.trim();
      if (!name) throw new LinkError('vendor', 'The name cannot be empty');
      const run = host.run();
      await client.setDeviceName(name, commandId);
      const r = await client.deviceName();
      if (run.alive()) detail.setState((s) => ({ identity: { ...s.identity, name: r.name } }));
      return `renamed to ${r.name}`;
    },
  });

  // Settings: the Safety tab shows the query's answer, which these make stale (read again at once
  // where it is shown, else after the next idle poll).
  const switchCommand = (sensor: Sensor, on: boolean) => {
    const sw = SWITCH[sensor];
    return cmds.define({
      id: `xtool.${sensor}-stop-${on ? 'on' : 'off'}`,
      label: `Turn the ${sw.words} ${on ? 'on' : 'off'}`,
      hazard: on ? 'adjust' : 'dangerous',
      role: 'supervisor',
      confirm: on
        ? false
        : `Turn the ${sw.words} OFF? Without it ${sw.risk}. Only do this for a reason, and turn it back on afterwards.`,
      invalidates: [SETTINGS_KEY],
      perform: async (_a, { commandId }) => {
        await client.setSystem(sw.action, on ? 1 : 0, commandId);
        return `${sw.words} ${on ? 'on' : 'off'}`;
      },
    });
  };

  const byteCommand = (id: string, label: string, action: ByteAction) =>
    cmds.define<{ value: number }>({
      id,
      label,
      hazard: 'adjust',
      role: 'supervisor',
      invalidates: [SETTINGS_KEY],
      perform: async (a, { commandId }) => {
        checkByte(a.value, label);
        await client.setSystem(action, a.value, commandId);
        return `${label}: ${a.value}`;
      },
    });

  const limitStopOn = switchCommand('limit', true);
  const limitStopOff = switchCommand('limit', false);
  const tiltStopOn = switchCommand('tilt', true);
  const tiltStopOff = switchCommand('tilt', false);
  const movingStopOn = switchCommand('moving', true);
  const movingStopOff = switchCommand('moving', false);
  const tiltThreshold = byteCommand('xtool.tilt-threshold', 'Tilt threshold', 'setTiltCheckThreshold');
  const movingThreshold = byteCommand(
    'xtool.moving-threshold',
    'Movement threshold',
    'setMovingCheckThreshold',
  );
  const flameMode = byteCommand('xtool.flame-mode', 'Flame alarm mode', 'setFlameAlarmMode');

  const flameSensitivity = cmds.define<{ level: 1 | 2 }>({
    id: 'xtool.flame-sensitivity',
    label: 'Set the flame sensor sensitivity',
    hazard: 'adjust',
    role: 'supervisor',
    invalidates: [SETTINGS_KEY],
    perform: async (a, { commandId }) => {
      await client.setSystem('setFlameAlarmSensitivity', a.level, commandId);
      return `flame sensitivity ${flameSensitivityWords(a.level)}`;
    },
  });

  const flameAlarmOff = cmds.define({
    id: 'xtool.flame-alarm-off',
    label: 'Turn the flame alarm off',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm:
      'Turn the flame alarm OFF? The laser will keep firing if the work piece catches fire. ' +
      'Never leave the laser unattended with the flame alarm off.',
    invalidates: [SETTINGS_KEY],
    perform: async (_a, { commandId }) => {
      await client.setSystem('setFlameAlarmSensitivity', 3, commandId);
      return 'flame alarm off';
    },
  });

  const upgrade = cmds.define<{ file: Blob; name: string }>({
    id: 'xtool.upgrade',
    label: 'Upgrade firmware',
    hazard: 'dangerous',
    role: 'supervisor',
    confirmTwice: true,
    confirm: (a) =>
      `Flash ${a.name} (${a.file.size} bytes) onto the laser? It runs firmware ${detail.getState().identity.version ?? '(unknown)'} now. ` +
      'A wrong or interrupted file can leave the laser unusable.',
    available: ({ xtool }) => (xtool.machine.state === 'idle' ? true : 'Only when the laser is idle'),
    perform: async (a, { commandId }) => {
      const run = host.run();
      const upd = (u: Partial<UploadState>) => {
        if (run.alive()) detail.setState((s) => (s.upgrade ? { upgrade: { ...s.upgrade, ...u } } : {}));
      };
      if (run.alive()) {
        const start: UploadState = {
          name: a.name,
          path: '/upgrade',
          loaded: 0,
          total: a.file.size,
          phase: 'uploading',
          message: null,
        };
        detail.setState({ upgrade: start });
      }
      try {
        const r = await client.upgrade(a.file, a.name, commandId, (p) =>
          upd({ loaded: p.loaded, total: p.total }),
        );
        if (r !== 'OK') throw new LinkError('vendor', 'The laser refused the firmware (it answered "FAIL")');
        upd({ phase: 'done', message: 'Firmware accepted. The laser restarts; it is offline for a moment.' });
        return 'firmware accepted';
      } catch (e) {
        upd({ phase: 'failed', message: describeError(e) });
        throw e;
      }
    },
  });

  return {
    all: cmds.all,
    pause,
    resume,
    stopJob,
    upload,
    deleteFile,
    runFile,
    gcode,
    setName,
    limitStopOn,
    limitStopOff,
    tiltStopOn,
    tiltStopOff,
    movingStopOn,
    movingStopOff,
    tiltThreshold,
    movingThreshold,
    flameMode,
    flameSensitivity,
    flameAlarmOff,
    upgrade,
  };
}

export type XtoolCommands = ReturnType<typeof xtoolCommands>;
