import type { CommandDecl } from '../../../fleet/commands';
import { useBlockedReason } from '../../../fleet/kernel';
import { CommandButton, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Notice, formatNumber, type Tone } from '../../../ui';
import { JobFacts } from '../../../fleet/JobFacts';
import { useJobWords } from '../../../fleet/job-facts';
import { decodeEnum, statLabel } from '../codes';
import type { G2coreSession } from '../session';
import { isStuckInRun } from '../commands';

/** Colour of each machine state (stat). */
export function statTone(stat: number | null): Tone {
  switch (stat) {
    case 1:
    case 3:
    case 4:
      return 'ok';
    case 5:
    case 7:
    case 8:
    case 9:
    case 10:
      return 'info';
    case 6:
    case 11:
      return 'paused';
    case 2:
    case 12:
    case 13:
      return 'bad';
    default:
      return 'muted';
  }
}

const numOrNull = (v: unknown): number | null => (typeof v === 'number' && Number.isFinite(v) ? v : null);

export function StatBadge({ session }: { session: G2coreSession }) {
  const stat = useStoreSelect(session.detail, (d) => numOrNull(d.sr.stat));
  return (
    // The same state pill as every family's (ui-badge), not drawn like a button.
    <span className={`ui-badge g2-stat tone-${statTone(stat)}`} data-testid="g2-stat" data-stat={stat ?? ''}>
      {statLabel(stat)}
    </span>
  );
}

/** Work positions (large) and machine positions (small) of every enabled axis. */
export function Dro({ session, compact }: { session: G2coreSession; compact?: boolean }) {
  const { axes, sr } = useStoreSelect(session.detail, (d) => ({ axes: d.axes, sr: d.sr }));
  const units = numOrNull(sr.unit) === 0 ? 'in' : 'mm';
  return (
    <div className="g2-dro" data-testid="g2-dro">
      {axes.map((a) => {
        const work = numOrNull(sr[`pos${a}`]);
        const mach = numOrNull(sr[`mpo${a}`]);
        const rotary = !'xyz'.includes(a);
        return (
          <div className="axis" key={a} data-testid={`dro-${a}`}>
            <div className="name">{a.toUpperCase()}</div>
            <div className="work" data-testid={`dro-${a}-work`}>
              {formatNumber(work, 3)}
            </div>
            {!compact && mach !== null && (
              <div className="mach" data-testid={`dro-${a}-machine`}>
                machine {formatNumber(mach, 3)} {rotary ? '°' : units}
              </div>
            )}
          </div>
        );
      })}
    </div>
  );
}

export function ModalState({ session }: { session: G2coreSession }) {
  const sr = useStoreSelect(session.detail, (d) => d.sr);
  const units = numOrNull(sr.unit) === 0 ? 'in' : 'mm';
  const n = (k: string) => numOrNull(sr[k]);
  const items: [string, string][] = [
    ['Velocity', `${formatNumber(n('vel'), 1)} ${units}/min`],
    ['Feed', `${formatNumber(n('feed'), 1)} ${units}/min`],
    ['Line', n('line') === null ? '—' : String(n('line'))],
    ['Units', decodeEnum('unit', n('unit'))],
    ['Coordinate system', decodeEnum('coor', n('coor'))],
    ['Motion mode', decodeEnum('momo', n('momo'))],
    ['Plane', decodeEnum('plan', n('plan'))],
    ['Distance mode', decodeEnum('dist', n('dist'))],
    ['Arc distance', decodeEnum('admo', n('admo'))],
    ['Feed rate mode', decodeEnum('frmo', n('frmo'))],
    ['Path control', decodeEnum('path', n('path'))],
  ];
  return (
    <dl className="ui-kv" data-testid="g2-modal">
      {items
        .filter(([, v]) => v !== '—')
        .map(([k, v]) => (
          <div key={k} style={{ display: 'contents' }}>
            <dt>{k}</dt>
            <dd>{v}</dd>
          </div>
        ))}
    </dl>
  );
}

/**
 * Clear alarm (and a stuck board's reset): feedhold, cycle start and kill are the machine page's
 * job control row (src/app/kiosk/JobControls.tsx), the same in every family.
 */
export function Controls({ session }: { session: G2coreSession }) {
  const { commands: runner, snapshot } = session.ctx;
  // A serial board the gateway reports stuck in run: its hard reset, for a supervisor (issue 19).
  const stuck = useSnapshot(session.ctx, isStuckInRun);
  return (
    <div className="g2-controls" data-testid="g2-controls">
      <CommandButton runner={runner} snapshot={snapshot} command={session.clearAlarm} args={undefined}>
        Clear alarm
      </CommandButton>
      {stuck && (
        <CommandButton
          runner={runner}
          snapshot={snapshot}
          command={session.resetBoard}
          args={undefined}
          variant="danger"
        >
          Reset the board
        </CommandButton>
      )}
    </div>
  );
}

export function Alarms({ session }: { session: G2coreSession }) {
  const alarms = useSnapshot(session.ctx, (s) => s.alarms);
  if (alarms.length === 0) return null;
  return (
    <>
      {alarms.map((a) => (
        <Notice
          key={a.id}
          tone={a.severity === 'critical' ? 'bad' : 'warn'}
          title={a.message}
          testId={`alarm-${a.id}`}
        >
          {a.clears ? `What clears it: ${a.clears}.` : null}
        </Notice>
      ))}
    </>
  );
}

export function JobProgress({ session }: { session: G2coreSession }) {
  const job = useSnapshot(session.ctx, (s) => s.job);
  const lines = useStoreSelect(session.detail, (d) => {
    const j = d.jobs.find((x) => x.state.state === 'running' || x.state.state === 'paused');
    return j ? { done: j.done ?? null, total: j.lines ?? null } : null;
  });
  const words = useJobWords(session.machine.id, job);
  if (!job) return null;
  return (
    <div data-testid="g2-job-progress">
      <div className="ui-row" style={{ justifyContent: 'space-between' }}>
        <strong>{words?.name}</strong>
        <span data-testid="g2-job-lines">
          {lines?.done ?? '—'} / {lines?.total ?? '—'} lines
        </span>
      </div>
      <JobFacts machine={session.machine.id} job={job} />
    </div>
  );
}

/**
 * Why a command cannot run right now, in words on screen: the button's own title only shows on
 * hover, which a touch tablet does not have.
 */
export function WhyNot<A>({
  session,
  command,
  testId,
}: {
  session: G2coreSession;
  command: CommandDecl<A>;
  testId?: string;
}) {
  // Follows exactly what the command's availability reads: the runner, the snapshot and the
  // stores the command names (defineCommands), so the words never lag behind the button.
  const reason = useBlockedReason(session.ctx.commands, session.ctx.snapshot, command);
  if (!reason) return null;
  return (
    <div className="ui-muted" style={{ margin: '8px 0' }} data-testid={testId ?? `g2-whynot-${command.id}`}>
      {reason}
    </div>
  );
}
