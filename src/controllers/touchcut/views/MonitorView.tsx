import { useEffect, useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { useNow, useStoreSelect } from '../../../fleet/react';
import { Button, DataTable, EmptyState, Notice, Panel, formatAge } from '../../../ui';
import type { TouchcutSession } from '../session';
import { unitLabel, type Axis, type IoPoint } from '../wire';
import { axisName, num, READ_ONLY, UnitsPicker, YesNo } from './common';

const SECTIONS = [
  { id: 'axes', label: 'Axes', field: 'axes.*' },
  { id: 'din', label: 'Digital in', field: 'io.din' },
  { id: 'dout', label: 'Digital out', field: 'io.dout' },
  { id: 'ain', label: 'Analogue in', field: 'io.ain' },
  { id: 'aout', label: 'Analogue out', field: 'io.aout' },
] as const;
type SectionId = (typeof SECTIONS)[number]['id'];

/** Axes and I/O, refreshed about twice a second while on screen, asking only for what is shown (`fields`). */
export function MonitorView({ session }: TabProps<TouchcutSession>) {
  const [shown, setShown] = useState<SectionId[]>(['axes', 'din', 'dout']);
  const { data, at, error } = useStoreSelect(session.monitor.store, (s) => ({
    data: s.data,
    at: s.at,
    error: s.error,
  }));
  const now = useNow(1000);
  useEffect(() => session.monitor.acquire(), [session]);
  useEffect(() => {
    session.monitor.setFields(SECTIONS.filter((s) => shown.includes(s.id)).map((s) => s.field));
  }, [session, shown]);
  const toggle = (id: SectionId) =>
    setShown((cur) => (cur.includes(id) ? cur.filter((x) => x !== id) : [...cur, id]));
  const units = data?.units;
  return (
    <div className="tc-stack" data-testid="touchcut-monitor">
      <div className="ui-row">
        {SECTIONS.map((s) => (
          <Button
            key={s.id}
            small={false}
            variant={shown.includes(s.id) ? 'primary' : 'secondary'}
            aria-pressed={shown.includes(s.id)}
            onClick={() => toggle(s.id)}
          >
            {s.label}
          </Button>
        ))}
        <UnitsPicker />
        <span className="ui-muted small">{at ? `updated ${formatAge(at, now)}` : 'waiting…'}</span>
      </div>
      {error && <Notice tone="warn">{error}</Notice>}
      {shown.length === 0 && <EmptyState>Pick what to watch.</EmptyState>}
      {data && shown.includes('axes') && (
        <Panel title="Axes">
          <AxesTable axes={data.axes} units={units} />
          {data.axes
            .filter((a) => a.io.din.length + a.io.dout.length + a.io.ain.length + a.io.aout.length > 0)
            .map((a, i) => (
              <details key={`${a.name ?? ''}-${i}`}>
                <summary>I/O of the {axisName(a.name, a.index ?? i + 1).toLowerCase()}</summary>
                {(['din', 'dout', 'ain', 'aout'] as const).map((g) =>
                  a.io[g].length > 0 ? (
                    <IoTable key={g} points={a.io[g]} analogue={g === 'ain' || g === 'aout'} units={units} />
                  ) : null,
                )}
              </details>
            ))}
        </Panel>
      )}
      {data &&
        SECTIONS.filter((s) => s.id !== 'axes' && shown.includes(s.id)).map((s) => (
          <Panel key={s.id} title={s.label}>
            <IoTable
              points={data.io[s.id as Exclude<SectionId, 'axes'>]}
              analogue={s.id === 'ain' || s.id === 'aout'}
              units={units}
            />
          </Panel>
        ))}
      {READ_ONLY}
    </div>
  );
}

function Ratio(props: { value: number | undefined; limit: number | undefined; digits?: number }) {
  const r = props.value !== undefined && props.limit ? Math.abs(props.value) / Math.abs(props.limit) : null;
  const tone = r === null ? undefined : r >= 1 ? 'var(--bad)' : r >= 0.8 ? 'var(--warn)' : undefined;
  return (
    <span style={{ color: tone }} title={r === null ? undefined : `${Math.round(r * 100)} % of the limit`}>
      {num(props.value, props.digits ?? 3)} / {num(props.limit, props.digits ?? 3)}
    </span>
  );
}

function flag(on: boolean | undefined, label: string) {
  return on ? label : null;
}

export function AxesTable({ axes, units }: { axes: Axis[]; units: string | undefined }) {
  return (
    <DataTable
      testId="touchcut-axes"
      rowKey={(a, i) => `${a.name ?? ''}-${a.index ?? i}`}
      rows={axes}
      empty="No axes in the answer."
      columns={[
        {
          key: 'name',
          label: 'Axis',
          render: (a) => <span title={a.address}>{axisName(a.name, a.index)}</span>,
        },
        {
          key: 'actualPos',
          label: `Position (${unitLabel(axes[0]?.unitType, units)})`,
          align: 'right',
          render: (a) => num(a.actualPos, 3),
        },
        { key: 'commandedPos', label: 'Commanded', align: 'right', render: (a) => num(a.commandedPos, 3) },
        {
          key: 'posError',
          label: 'Error / limit',
          align: 'right',
          render: (a) => <Ratio value={a.posError} limit={a.errorLimit} digits={4} />,
        },
        {
          key: 'actualVel',
          label: `Velocity (${unitLabel(axes[0]?.speedUnitType, units)})`,
          align: 'right',
          render: (a) => num(a.actualVel, 1),
        },
        {
          key: 'torque',
          label: 'Torque / limit',
          align: 'right',
          render: (a) => <Ratio value={a.torque} limit={a.torqueLimit} digits={1} />,
        },
        { key: 'isEnabled', label: 'Enabled', render: (a) => <YesNo value={a.isEnabled} /> },
        { key: 'isMoving', label: 'Moving', render: (a) => <YesNo value={a.isMoving} tone="warn" /> },
        {
          key: 'inputs',
          label: 'Home / limits',
          render: (a) =>
            [
              flag(a.isHomeInputOn, 'home'),
              flag(a.isRevLimInputOn, 'reverse limit'),
              flag(a.isFwdLimInputOn, 'forward limit'),
              flag(a.isRevSoftLimOn, 'reverse soft limit'),
              flag(a.isFwdSoftLimOn, 'forward soft limit'),
              flag(a.isPosErrorInputOn, 'position error'),
            ]
              .filter(Boolean)
              .join(', ') || '—',
        },
        {
          key: 'can',
          label: 'Can move',
          render: (a) =>
            [a.canMoveFwd ? 'forward' : null, a.canMoveRev ? 'reverse' : null].filter(Boolean).join(' / ') ||
            'no',
        },
        {
          key: 'errorCode',
          label: 'Error code',
          align: 'right',
          render: (a) =>
            a.errorCode && a.errorCode !== '0' ? (
              <strong style={{ color: 'var(--bad)' }}>{a.errorCode}</strong>
            ) : (
              '0'
            ),
        },
      ]}
    />
  );
}

function IoTable({
  points,
  analogue,
  units,
}: {
  points: IoPoint[];
  analogue: boolean;
  units: string | undefined;
}) {
  return (
    <DataTable
      rowKey={(p, i) => `${p.address ?? ''}-${p.name ?? ''}-${i}`}
      rows={points}
      empty="No points in the answer."
      columns={[
        { key: 'name', label: 'Name', render: (p) => p.name ?? '—' },
        { key: 'address', label: 'Address', render: (p) => <span className="mono">{p.address ?? '—'}</span> },
        analogue
          ? {
              key: 'value',
              label: 'Value',
              align: 'right',
              render: (p) =>
                `${typeof p.value === 'number' ? num(p.value, 3) : String(p.value ?? '—')} ${unitLabel(p.unitType, units)}`,
            }
          : {
              key: 'value',
              label: 'State',
              render: (p) => (
                <YesNo value={typeof p.value === 'number' ? p.value !== 0 : p.value} yes="ON" no="off" />
              ),
            },
        ...(analogue
          ? [
              {
                key: 'scale',
                label: 'Scale',
                align: 'right' as const,
                render: (p: IoPoint) => num(p.scale, 3),
              },
            ]
          : []),
      ]}
    />
  );
}
