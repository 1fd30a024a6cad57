import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { JobFacts } from '../../../fleet/JobFacts';
import { describeError } from '../../../fleet/errors';
import { CommandButton, useCan, useNow, useSnapshot, useStoreSelect } from '../../../fleet/react';
import {
  Badge,
  Button,
  DataTable,
  Field,
  KeyValues,
  Notice,
  Panel,
  ProgressBar,
  formatAge,
  formatPercent,
  formatTime,
} from '../../../ui';
import { activityOf, hasProgram, severityOf } from '../normalize';
import type { ChangePasswordArgs, TouchcutSession } from '../session';
import { progressFraction, unitLabel, type Pose } from '../wire';
import { num, READ_ONLY, UnitsPicker, YesNo } from './common';
import { LoginForm } from './LoginForm';

const AXES = ['X', 'Y', 'Z'];
const ROT = ['A', 'B', 'C'];

function poseRows(commanded: Pose | null | undefined, actual: Pose | null | undefined) {
  const rows: Array<{
    axis: string;
    commanded: number | undefined;
    actual: number | undefined;
    rot: boolean;
  }> = [];
  const n = Math.max(commanded?.vec.length ?? 0, actual?.vec.length ?? 0);
  for (let i = 0; i < n; i++)
    rows.push({
      axis: AXES[i] ?? `#${i + 1}`,
      commanded: commanded?.vec[i],
      actual: actual?.vec[i],
      rot: false,
    });
  const r = Math.max(commanded?.rot.length ?? 0, actual?.rot.length ?? 0);
  for (let i = 0; i < r; i++)
    rows.push({
      axis: ROT[i] ?? `rot ${i + 1}`,
      commanded: commanded?.rot[i],
      actual: actual?.rot[i],
      rot: true,
    });
  return rows;
}

export function StatusView({ session }: TabProps<TouchcutSession>) {
  const { status, statusAt, notice } = useStoreSelect(session.store, (s) => ({
    status: s.status,
    statusAt: s.statusAt,
    notice: s.notice,
  }));
  const snap = useSnapshot(session.ctx, (s) => ({ alarms: s.alarms, job: s.job, link: s.link }));
  const now = useNow(1000);
  if (!status) {
    return (
      <div className="tc-stack">
        {notice && <Notice tone="info">{notice}</Notice>}
        <Notice tone="info" title="Waiting for the first status">
          {snap.link === 'needs-login'
            ? 'Log in to TouchCut above to see the machine.'
            : 'Connecting to TouchCut…'}
        </Notice>
        <AuthPanel session={session} />
      </div>
    );
  }
  const units = status.units;
  const len = unitLabel('utLength', units);
  const feed = unitLabel('utFeed', units);
  const act = activityOf(status);
  const progress = progressFraction(status.programProgress);
  return (
    <div className="tc-stack" data-testid="touchcut-status">
      {notice && <Notice tone="info">{notice}</Notice>}
      {snap.alarms.length > 0 && (
        <Panel title="Messages from the machine">
          <ul className="tc-msgs" data-testid="touchcut-messages">
            {status.msgStatus.map((m, i) => {
              const sev = severityOf(m);
              return (
                <li key={`${m.key ?? ''}-${i}`}>
                  <Badge tone={sev === 'critical' ? 'bad' : sev === 'warning' ? 'warn' : 'info'}>{sev}</Badge>{' '}
                  {m.msg || m.key}
                  {m.key && m.msg && m.key !== m.msg && <span className="ui-muted small"> ({m.key})</span>}
                </li>
              );
            })}
          </ul>
        </Panel>
      )}
      <div className="ui-grid">
        <Panel
          title="Machine"
          actions={
            <span className="ui-muted small" title={formatTime(statusAt)}>
              {formatAge(statusAt, now)}
            </span>
          }
        >
          <div className="tc-big" data-testid="touchcut-state">
            {status.stateName || status.machineState || '—'}
          </div>
          <KeyValues
            items={[
              ['Machine state', act.activity === 'unknown' ? act.label : status.machineState],
              ['Program state', status.programState],
              ['Override', status.programOverride],
              ['Homed', <YesNo key="h" value={status.isHomed} tone="ok" no="not homed" />],
              ['Current user', status.currentUser],
              ['Units', units ?? '—'],
            ]}
          />
        </Panel>
        <Panel title="Program">
          <div className="tc-big">
            {hasProgram(status.programName) ? status.programName : 'No active program'}
          </div>
          {/* The server's job record, as every view says it (fleet/job-facts.ts). */}
          <JobFacts machine={session.machine.id} job={snap.job ?? null} />
          {!snap.job && <ProgressBar value={progress} label="program progress" />}
          <KeyValues
            items={[
              ['Feed rate', `${num(status.feedrate, 1)} ${feed}`],
              [
                'Feed override',
                status.feedOverride === undefined ? '—' : formatPercent(status.feedOverride / 100),
              ],
            ]}
          />
        </Panel>
        <Panel title="Tool and material">
          <KeyValues
            items={[
              [
                'Tool',
                `${status.toolName ?? '—'}${status.toolIndex !== undefined ? ` (index ${status.toolIndex})` : ''}`,
              ],
              ['Tool on', <YesNo key="t" value={status.toolOn} yes="ON" no="off" tone="warn" />],
              ['Material', status.material ?? status.materialName],
              [
                'Thickness',
                status.materialThickness === undefined ? '—' : `${num(status.materialThickness, 3)} ${len}`,
              ],
              ['Carriages spaced', status.spacedCarriages.join(', ') || '—'],
              ['Carriages active', status.activeCarriages.join(', ') || '—'],
              ['Height control auto', <YesNo key="hc" value={status.heightControlAuto} />],
              ['Dross bin mode', status.drossBinMode],
            ]}
          />
        </Panel>
        <Panel title={`Position (${len}, rotation °)`}>
          <DataTable
            testId="touchcut-positions"
            rowKey={(r) => r.axis}
            rows={poseRows(status.commandedPos, status.actualPos)}
            columns={[
              { key: 'axis', label: 'Axis' },
              { key: 'commanded', label: 'Commanded', align: 'right', render: (r) => num(r.commanded, 3) },
              { key: 'actual', label: 'Actual', align: 'right', render: (r) => num(r.actual, 3) },
            ]}
          />
          <KeyValues
            items={[
              [
                'Plate origin',
                status.plateOrigin
                  ? `${status.plateOrigin.vec.map((v) => num(v, 2)).join(', ')} ${len}`
                  : '—',
              ],
              [
                'Plate origin rotation',
                status.plateOrigin ? status.plateOrigin.rot.map((v) => num(v, 2)).join(', ') : '—',
              ],
              [
                'Plate rotation',
                status.plateRotation === undefined ? '—' : `${num(status.plateRotation, 2)}°`,
              ],
            ]}
          />
        </Panel>
      </div>
      <div className="ui-grid">
        <AuthPanel session={session} />
        <InfoPanel session={session} />
      </div>
      {READ_ONLY}
    </div>
  );
}

function InfoPanel({ session }: TabProps<TouchcutSession>) {
  const info = useStoreSelect(session.store, (s) => s.info);
  if (!info) return null;
  const c = info.contactInfo;
  return (
    <Panel title="Machine information">
      <KeyValues
        items={[
          ['Software', [info.exeName, info.exeVersion].filter(Boolean).join(' ')],
          ['Licensed to', info.licensedTo],
          ['PrimeCut', info.primeCutInfo],
          ['Registration', info.registrationInfo],
          [
            'Tools',
            info.tools
              .map((t) => `${t.toolName ?? '?'} (${t.toolType ?? '?'}, ${t.position ?? '?'})`)
              .join('; ') || '—',
          ],
          ['Service contact', c ? [c.companyName, c.phone, c.email].filter(Boolean).join(' · ') || '—' : '—'],
        ]}
      />
    </Panel>
  );
}

/**
 * Who the console is to TouchCut: the gateway's API key, or a TouchCut user login the gateway
 * holds for the machine (shared by every viewer; the token never reaches this browser).
 */
export function AuthPanel({ session }: TabProps<TouchcutSession>) {
  const auth = useStoreSelect(session.store, (s) => s.auth);
  const now = useNow(5000);
  const [open, setOpen] = useState(false);
  // Logging the machine in or out changes what every viewer reads: an operator's (access.ts).
  const mayLogIn = useCan('operator');
  const [busy, setBusy] = useState(false);
  const [error, setError] = useState<string | null>(null);
  const logout = async () => {
    setBusy(true);
    setError(null);
    try {
      await session.logout();
    } catch (e) {
      setError(describeError(e));
    } finally {
      setBusy(false);
    }
  };
  return (
    <Panel title="TouchCut access" actions={<UnitsPicker />} testId="touchcut-auth">
      {auth.mode === 'user' ? (
        <>
          <p>
            Logged in to TouchCut as <strong data-testid="touchcut-user">{auth.user}</strong>
            {auth.expiresAt && (
              <span className="ui-muted small" data-testid="touchcut-login-expiry">
                {' '}
                · login valid until {formatTime(auth.expiresAt)}
                {auth.expiresAt < now ? ' (expired)' : ''}
              </span>
            )}
          </p>
          <p className="ui-muted small">
            The console's server holds this login for every viewer of the machine.
          </p>
          {error && (
            <p role="alert" style={{ color: 'var(--bad)' }} data-testid="touchcut-logout-error">
              {error}
            </p>
          )}
          <div className="ui-row">
            {mayLogIn && (
              <Button onClick={() => void logout()} busy={busy} disabled={busy} data-testid="touchcut-logout">
                Log out of TouchCut
              </Button>
            )}
            <Button onClick={() => setOpen(!open)} aria-expanded={open}>
              Change password…
            </Button>
          </div>
          {open && <ChangePasswordForm session={session} onDone={() => setOpen(false)} />}
        </>
      ) : (
        <>
          <p className="ui-muted">
            Using the console's API key for this machine (held by the console's server, never by this
            browser). Log in as a TouchCut user to use your own privileges.
          </p>
          {mayLogIn && (
            <Button onClick={() => setOpen(!open)} aria-expanded={open} data-testid="touchcut-login-open">
              Log in as a TouchCut user…
            </Button>
          )}
          {mayLogIn && open && <LoginForm session={session} />}
        </>
      )}
    </Panel>
  );
}

function ChangePasswordForm({ session, onDone }: TabProps<TouchcutSession> & { onDone: () => void }) {
  const [args, setArgs] = useState<ChangePasswordArgs>({
    oldPassword: '',
    newPassword: '',
    confirmPassword: '',
  });
  const [done, setDone] = useState<string | null>(null);
  const mismatch = args.confirmPassword !== '' && args.newPassword !== args.confirmPassword;
  const set = (k: keyof ChangePasswordArgs) => (e: React.ChangeEvent<HTMLInputElement>) =>
    setArgs({ ...args, [k]: e.target.value });
  return (
    <form className="tc-form" onSubmit={(e) => e.preventDefault()} data-testid="touchcut-change-password">
      <Field label="Current password">
        {(id) => (
          <input
            id={id}
            className="ui-input"
            type="password"
            autoComplete="current-password"
            value={args.oldPassword}
            onChange={set('oldPassword')}
          />
        )}
      </Field>
      <Field label="New password">
        {(id) => (
          <input
            id={id}
            className="ui-input"
            type="password"
            autoComplete="new-password"
            value={args.newPassword}
            onChange={set('newPassword')}
          />
        )}
      </Field>
      <Field label="Confirm new password" error={mismatch ? 'Does not match the new password' : undefined}>
        {(id) => (
          <input
            id={id}
            className="ui-input"
            type="password"
            autoComplete="new-password"
            value={args.confirmPassword}
            onChange={set('confirmPassword')}
            aria-invalid={mismatch}
          />
        )}
      </Field>
      <div className="ui-row">
        <CommandButton
          runner={session.ctx.commands}
          snapshot={session.ctx.snapshot}
          command={session.changePassword}
          args={args}
          variant="primary"
          onDone={(r) => {
            setDone(r);
            setArgs({ oldPassword: '', newPassword: '', confirmPassword: '' });
            onDone();
          }}
        />
        {done && <span className="ui-muted">{done}</span>}
      </div>
    </form>
  );
}
