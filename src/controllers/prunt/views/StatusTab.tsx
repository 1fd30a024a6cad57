import { useStore } from 'zustand';
import type { TabProps } from '../../../fleet/contract';
import { formatAge, formatNumber, Panel } from '../../../ui';
import { useNow } from '../../../fleet/react';
import type { PruntSession } from '../session';
import type { StatusEntry, StatusScalar } from '../status';
import { RateSelect, StartupBanner, useWatchLive } from './common';
import { LiveChart } from './LiveChart';
import './prunt.css';

/** Status rendered from the status schema: module → group → value with unit and description. */
export function StatusTab({ session }: TabProps<PruntSession>) {
  useWatchLive(session);
  const model = useStore(session.store, (s) => s.statusModel);
  const at = useStore(session.store, (s) => s.statusAt);
  const now = useNow(1000);
  if (!model) return <p className="ui-muted">Waiting for the status schema…</p>;
  return (
    <div className="pr-grid" data-testid="prunt-status">
      <StartupBanner session={session} />
      {model.map((m) => (
        <Panel key={m.name} title={m.name} className="pr-wide">
          {m.groups.map((g) => (
            <div key={g.name} className="pr-status-group">
              <h3>{g.name.replace(/_/g, ' ')}</h3>
              <table className="ui-table">
                <tbody>
                  {g.entries.map((e) => (
                    <StatusRow key={e.name} session={session} entry={e} />
                  ))}
                </tbody>
              </table>
            </div>
          ))}
        </Panel>
      ))}
      <Panel title="Live" actions={<RateSelect session={session} />} className="pr-wide">
        <p className="ui-muted">Last status {formatAge(at, now)}.</p>
        <LiveChart session={session} />
      </Panel>
    </div>
  );
}

function StatusRow(props: { session: PruntSession; entry: StatusEntry }) {
  const e = props.entry;
  const v = useStore(props.session.store, (s) => s.status[e.module]?.[e.group]?.[e.name]);
  return (
    <tr>
      <th scope="row">{e.name}</th>
      <td className="num mono" data-testid={`status-${e.module}-${e.group}-${e.name}`}>
        {v === undefined || v === null ? <span className="ui-muted">—</span> : show(v, e)}
      </td>
      <td className="ui-muted">
        {e.description}
        {(v === undefined || v === null) && (
          <div>
            <em>Not reported{e.condition ? `: ${e.condition}` : ' yet.'}</em>
          </div>
        )}
      </td>
    </tr>
  );
}

function show(v: StatusScalar, e: StatusEntry): string {
  if (typeof v === 'boolean') return v ? 'yes' : 'no';
  if (typeof v === 'number') {
    const unit = e.unit === 'celsius' ? '°C' : e.unit;
    // Integers as they come (counts, ids: no grouping); decimals in the console's locale.
    if (e.kind === 'Integer' || Number.isInteger(v)) return unit ? `${v} ${unit}` : String(v);
    return formatNumber(v, Math.abs(v) < 10 ? 3 : 2, unit || undefined);
  }
  return v === '' ? '(none)' : String(v);
}
