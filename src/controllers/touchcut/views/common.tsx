import { useEffect, useState, type ReactNode } from 'react';
import { useStore } from 'zustand';
import {
  Badge,
  Button,
  ScrollRegion,
  csvFromColumns,
  downloadCsv,
  formatDecimal,
  type CsvColumn,
} from '../../../ui';
import { setTouchcutUnits, touchcutUnits } from '../session';
import { UNITS_CHOICES, type UnitsChoice } from '../wire';

export function useUnits(): UnitsChoice {
  return useStore(touchcutUnits, (s) => s.units);
}

/** The per-user units choice (sent as `units`); values are shown in the unit the answer names. */
export function UnitsPicker() {
  const units = useUnits();
  return (
    <label className="tc-units">
      <span className="ui-muted small">Units</span>
      <select
        className="ui-input"
        value={units}
        onChange={(e) => setTouchcutUnits(e.target.value as UnitsChoice)}
        data-testid="touchcut-units"
      >
        {UNITS_CHOICES.map((u) => (
          <option key={u} value={u}>
            {u === 'default' ? 'TouchCut default' : u}
          </option>
        ))}
      </select>
    </label>
  );
}

/** TouchCut's axis names as people say them. */
const AXIS_WORDS: Record<string, string> = {
  axisLong: 'Long axis',
  axisShort: 'Short axis',
  axisTorch: 'Torch axis',
};

/**
 * An axis's name for people: "axisLong" → "Long axis"; another `axisSomeThing` → "Some thing
 * axis"; any other name as TouchCut sends it; no name → "Axis <index>".
 */
export function axisName(name: string | undefined, index?: string | number): string {
  if (name === undefined || name === '') return index === undefined ? 'Axis' : `Axis ${index}`;
  const known = AXIS_WORDS[name];
  if (known) return known;
  const m = /^axis([A-Z][A-Za-z0-9]*)$/.exec(name);
  if (!m?.[1]) return name;
  const words = m[1].replace(/([a-z0-9])([A-Z])/g, '$1 $2').toLowerCase();
  return `${words.charAt(0).toUpperCase()}${words.slice(1)} axis`;
}

/** TouchCut's field names (its "subject to change" JSON) as people read them. */
const KEY_WORDS: Record<string, string> = {
  activeProgram: 'Active program',
  fileId: 'File number',
  programs: 'Programs',
  units: 'Units',
  name: 'Name',
  total: 'Total',
};

/**
 * A field name of TouchCut's generic data for people: the phrase table, else a camelCase or
 * snake_case name split into words ("cutCount" → "Cut count"); the name TouchCut sends stays
 * the cell's title (a technician's hover).
 */
export function keyLabel(key: string): string {
  const known = KEY_WORDS[key];
  if (known) return known;
  if (axisName(key) !== key) return axisName(key);
  const words = key
    .replace(/([a-z0-9])([A-Z])/g, '$1 $2')
    .replace(/[_-]+/g, ' ')
    .trim()
    .toLowerCase();
  return words ? `${words.charAt(0).toUpperCase()}${words.slice(1)}` : key;
}

export function num(v: number | undefined | null, digits = 2): string {
  return formatDecimal(v, digits);
}

export function YesNo(props: {
  value: boolean | undefined;
  yes?: string;
  no?: string;
  tone?: 'ok' | 'warn' | 'bad';
}) {
  if (props.value === undefined) return <span className="ui-muted">—</span>;
  return (
    <Badge tone={props.value ? (props.tone ?? 'ok') : 'muted'} plain>
      {props.value ? (props.yes ?? 'yes') : (props.no ?? 'no')}
    </Badge>
  );
}

export function CsvButton<T>(props: { name: string; columns: readonly CsvColumn<T>[]; rows: readonly T[] }) {
  return (
    <Button
      small
      disabled={props.rows.length === 0}
      // A BOM: these files are opened in spreadsheets (operator and program names are not ASCII-only).
      onClick={() =>
        downloadCsv(`${props.name}.csv`, csvFromColumns(props.columns, props.rows, { bom: true }))
      }
      data-testid={`csv-${props.name.replace(/[^a-z0-9]+/gi, '-').toLowerCase()}`}
    >
      CSV
    </Button>
  );
}

/** An object URL for a blob, revoked when it changes or the component goes away. */
export function useObjectUrl(blob: Blob | null): string | null {
  const [url, setUrl] = useState<string | null>(null);
  useEffect(() => {
    if (!blob) {
      setUrl(null);
      return;
    }
    const u = URL.createObjectURL(blob);
    setUrl(u);
    return () => URL.revokeObjectURL(u);
  }, [blob]);
  return url;
}

export const READ_ONLY = (
  <p className="ui-muted small" data-testid="touchcut-read-only">
    TouchCut's REST API is read-only: the machine is started, stopped and set up at the machine. This console
    only watches.
  </p>
);

// ---------------------------------------------------------------------------------------------
// generic data ("interface subject to change")

function isRecord(v: unknown): v is Record<string, unknown> {
  return !!v && typeof v === 'object' && !Array.isArray(v);
}

function scalar(v: unknown): ReactNode {
  if (v === null || v === undefined) return <span className="ui-muted">—</span>;
  if (typeof v === 'boolean') return v ? 'yes' : 'no';
  // Integers as sent (ids, counts: no thousands separators); fractions rounded.
  if (typeof v === 'number') return Number.isInteger(v) ? String(v) : num(v, 3);
  if (typeof v === 'string') return v;
  return null;
}

/**
 * Renders whatever JSON came back as readable tables: arrays of objects become tables (columns =
 * union of keys), objects become key/value lists, nested values fold into <details>. Text is
 * rendered as text (React escapes it): nothing from the controller is ever HTML.
 */
export function DataTree(props: { value: unknown; depth?: number; label?: string }) {
  const depth = props.depth ?? 0;
  const v = props.value;
  const s = scalar(v);
  if (s !== null) return <>{s}</>;
  if (depth > 6) return <code className="small">{JSON.stringify(v).slice(0, 200)}</code>;
  if (Array.isArray(v)) {
    if (v.length === 0) return <span className="ui-muted">(empty)</span>;
    if (v.every(isRecord)) {
      const cols = [...new Set(v.flatMap((r) => Object.keys(r)))].slice(0, 16);
      return (
        <ScrollRegion className="ui-table-wrap" label={props.label ?? 'Table'}>
          <table className="ui-table">
            <thead>
              <tr>
                {cols.map((c) => (
                  <th key={c} scope="col" title={c}>
                    {keyLabel(c)}
                  </th>
                ))}
              </tr>
            </thead>
            <tbody>
              {v.map((row, i) => (
                <tr key={i}>
                  {cols.map((c) => (
                    <td key={c}>
                      <Nested value={row[c]} depth={depth + 1} label={keyLabel(c)} />
                    </td>
                  ))}
                </tr>
              ))}
            </tbody>
          </table>
        </ScrollRegion>
      );
    }
    return (
      <ul className="tc-list">
        {v.map((x, i) => (
          <li key={i}>
            <Nested value={x} depth={depth + 1} label={`#${i + 1}`} />
          </li>
        ))}
      </ul>
    );
  }
  if (isRecord(v)) {
    const entries = Object.entries(v);
    if (entries.length === 0) return <span className="ui-muted">(empty)</span>;
    return (
      <dl className="ui-kv">
        {entries.map(([k, x]) => (
          <div key={k} style={{ display: 'contents' }}>
            <dt title={k}>{keyLabel(k)}</dt>
            <dd>
              <Nested value={x} depth={depth + 1} label={keyLabel(k)} />
            </dd>
          </div>
        ))}
      </dl>
    );
  }
  return <code>{String(v)}</code>;
}

function Nested(props: { value: unknown; depth: number; label: string }) {
  const s = scalar(props.value);
  if (s !== null) return <>{s}</>;
  const size = Array.isArray(props.value)
    ? `${props.value.length} items`
    : `${Object.keys(props.value as object).length} fields`;
  // The first level is shown open (the stations, the program list); deeper levels fold.
  if (props.depth <= 1) return <DataTree value={props.value} depth={props.depth} />;
  return (
    <details>
      <summary>
        {props.label} ({size})
      </summary>
      <DataTree value={props.value} depth={props.depth} />
    </details>
  );
}
