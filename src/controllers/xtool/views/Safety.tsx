import { useState } from 'react';
import type { CommandDecl } from '../../../fleet/commands';
import type { TabProps } from '../../../fleet/contract';
import { describeError } from '../../../fleet/errors';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Badge, Button, Field, KeyValues, Notice, Panel, formatNumber } from '../../../ui';
import { LockableInput } from '../../../ui/Lockable';
import { GRID } from './layout';
import { useXtoolSettings } from '../queries';
import type { XtoolSession } from '../session';
import { flameSensitivityWords } from '../wire';

function OnOff({ value }: { value: boolean | undefined }) {
  if (value === undefined) return <Badge tone="muted">not reported by this firmware</Badge>;
  return value ? <Badge tone="ok">on</Badge> : <Badge tone="bad">OFF</Badge>;
}

/** A numeric setting 0–255 with its own Set button. */
function ByteSetting(props: {
  session: XtoolSession;
  label: string;
  hint: string;
  current: number | undefined;
  command: CommandDecl<{ value: number }>;
}) {
  const [text, setText] = useState('');
  const value = Number(text);
  const valid = text.trim() !== '' && Number.isInteger(value) && value >= 0 && value <= 255;
  const ctx = props.session.ctx;
  return (
    <Field
      label={`${props.label} (now ${props.current ?? 'not reported'})`}
      hint={props.hint}
      error={text && !valid ? 'A whole number from 0 to 255' : undefined}
    >
      {(id) => (
        <div className="ui-row">
          {/* Locked against touch on touch screens until its lock is tapped (src/ui/Lockable.tsx). */}
          <LockableInput
            id={id}
            lockLabel={props.label.toLowerCase()}
            inputMode="numeric"
            value={text}
            placeholder={props.current !== undefined ? String(props.current) : '0–255'}
            aria-invalid={Boolean(text) && !valid}
            onChange={(e) => setText(e.target.value)}
            style={{ width: 120 }}
          />
          {valid ? (
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={props.command}
              args={{ value }}
            >
              Set
            </CommandButton>
          ) : (
            <Button disabled>Set</Button>
          )}
        </div>
      )}
    </Field>
  );
}

/** Safety sensors, thresholds, flame alarm, red-cross offset, dot mode, device name. */
export function Safety({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  // The settings are an on-demand read (queries.ts): shown from cache, read again when stale and
  // after every settings command (they declare it).
  const settings = useXtoolSettings(session);
  const deviceName = useStoreSelect(session.detail, (s) => s.identity.name);
  const [name, setName] = useState('');
  const p = settings.data?.periphery ?? null;
  const d = {
    offset: settings.data?.offset ?? null,
    dotMode: settings.data?.dotMode ?? null,
    name: deviceName,
  };
  const run = (cmd: CommandDecl, label: string) => (
    <CommandButton runner={ctx.commands} snapshot={ctx.snapshot} command={cmd} args={undefined}>
      {label}
    </CommandButton>
  );
  const anyOff =
    p?.limitStopFlag === false ||
    p?.tiltStopFlag === false ||
    p?.movingStopFlag === false ||
    p?.flameAlarmSensitivity === 3;

  return (
    <div className="ui-grid" style={GRID} data-testid="xtool-safety">
      <Panel title="Safety sensors">
        {anyOff && (
          <Notice tone="bad" title="A safety sensor is off" testId="xtool-safety-off">
            The laser will not stop for everything it normally would. Do not leave it unattended.
          </Notice>
        )}
        {!p && (
          <Notice tone="warn" title={settings.loading ? 'Reading the settings…' : 'Settings not read yet'}>
            {settings.error ? describeError(settings.error) : null}
          </Notice>
        )}
        <table className="ui-table">
          <tbody>
            {(
              [
                ['Limit stop', p?.limitStopFlag, session.limitStopOn, session.limitStopOff],
                ['Tilt stop', p?.tiltStopFlag, session.tiltStopOn, session.tiltStopOff],
                ['Movement stop', p?.movingStopFlag, session.movingStopOn, session.movingStopOff],
              ] as const
            ).map(([label, value, on, off]) => (
              <tr key={label}>
                <th scope="row">{label}</th>
                <td>
                  <OnOff value={value} />
                </td>
                <td>
                  <div className="ui-row">
                    {value !== true && run(on, 'Turn on')}
                    {value !== false && run(off, 'Turn off')}
                  </div>
                </td>
              </tr>
            ))}
            <tr>
              <th scope="row">Flame alarm</th>
              <td>
                {p?.flameAlarmSensitivity === undefined ? (
                  <Badge tone="muted">not reported by this firmware</Badge>
                ) : (
                  <Badge tone={p.flameAlarmSensitivity === 3 ? 'bad' : 'ok'}>
                    {flameSensitivityWords(p.flameAlarmSensitivity)}
                  </Badge>
                )}
              </td>
              <td>
                <div className="ui-row">
                  {p?.flameAlarmSensitivity !== 1 && (
                    <CommandButton
                      runner={ctx.commands}
                      snapshot={ctx.snapshot}
                      command={session.flameSensitivity}
                      args={{ level: 1 }}
                    >
                      High
                    </CommandButton>
                  )}
                  {p?.flameAlarmSensitivity !== 2 && (
                    <CommandButton
                      runner={ctx.commands}
                      snapshot={ctx.snapshot}
                      command={session.flameSensitivity}
                      args={{ level: 2 }}
                    >
                      Low
                    </CommandButton>
                  )}
                  {p?.flameAlarmSensitivity !== 3 && run(session.flameAlarmOff, 'Turn off')}
                </div>
              </td>
            </tr>
          </tbody>
        </table>
      </Panel>
      <Panel title="Thresholds">
        <ByteSetting
          session={session}
          label="Tilt threshold"
          hint="0–255, default 15. The document does not say which way is more sensitive: stay near the default."
          current={p?.tiltThreshold}
          command={session.tiltThreshold}
        />
        <ByteSetting
          session={session}
          label="Movement threshold"
          hint="0–255, default 40. The document does not say which way is more sensitive: stay near the default."
          current={p?.movingThreshold}
          command={session.movingThreshold}
        />
        <ByteSetting
          session={session}
          label="Flame alarm mode"
          hint="The document does not know what the values mean; change only on advice."
          current={p?.flameAlarmMode}
          command={session.flameMode}
        />
      </Panel>
      <Panel title="Device">
        <KeyValues
          items={[
            [
              'Red-cross offset',
              d.offset ? `X ${formatNumber(d.offset.x, 1)} mm · Y ${formatNumber(d.offset.y, 1)} mm` : null,
            ],
            ['Dot mode', d.dotMode],
            ['Name', d.name],
          ]}
        />
        <p className="ui-muted">
          The offset and dot mode can only be read: the protocol document gives no way to set them.
        </p>
        <Field label="New name">
          {(id) => (
            <div className="ui-row">
              <input
                id={id}
                className="ui-input"
                value={name}
                maxLength={32}
                onChange={(e) => setName(e.target.value)}
              />
              {name.trim() ? (
                <CommandButton
                  runner={ctx.commands}
                  snapshot={ctx.snapshot}
                  command={session.setName}
                  args={{ name }}
                  onDone={() => setName('')}
                >
                  Rename
                </CommandButton>
              ) : (
                <Button disabled>Rename</Button>
              )}
            </div>
          )}
        </Field>
      </Panel>
    </div>
  );
}
