//! Build-time handles (`Var::of`, `Var::subs`, `Var::across`, the tables' `VARS`) against
//! the dictionary's own run-time lookup, for every entry of every registered device, and
//! the layout check that guards them.

use oxicat_devices::registry;
use oxicat_slave::{DataType, Od, OdType, Var};

/// Room for the largest device's application objects.
const ROOM: usize = 4096;

fn same<T: OdType>(od: &Od<ROOM>, index: u16, sub: u8) -> bool {
    let objects = od.def().objects;
    Var::<T>::of(objects, index, sub).entry() == od.var::<T>(index, sub).unwrap().entry()
}

#[test]
fn every_entry_of_every_device_resolves_at_build_time_where_the_dictionary_puts_it() {
    let mut checked = 0;
    for kit in registry::kits() {
        let def = (kit.def)(0);
        let od = Od::<ROOM>::new(def).unwrap();
        for o in def.objects {
            for e in o.entries {
                let (i, s) = (o.index, e.sub);
                let ok = match e.dtype {
                    DataType::Bool => same::<bool>(&od, i, s),
                    DataType::Int8 => same::<i8>(&od, i, s),
                    DataType::Int16 => same::<i16>(&od, i, s),
                    DataType::Int32 => same::<i32>(&od, i, s),
                    DataType::Int64 => same::<i64>(&od, i, s),
                    DataType::Unsigned8 => same::<u8>(&od, i, s),
                    DataType::Unsigned16 => same::<u16>(&od, i, s),
                    DataType::Unsigned32 => same::<u32>(&od, i, s),
                    DataType::Unsigned64 => same::<u64>(&od, i, s),
                    DataType::Real32 => same::<f32>(&od, i, s),
                    DataType::Real64 => same::<f64>(&od, i, s),
                    DataType::VisibleString | DataType::OctetString => continue,
                };
                assert!(ok, "{}: {i:#06x}:{s}", kit.name);
                checked += 1;
            }
        }
    }
    assert!(checked > 200, "only {checked} entries checked");
}

#[test]
fn a_dictionary_is_built_on_its_own_objects_only() {
    let kits = registry::kits();
    for a in kits {
        let od = Od::<ROOM>::new((a.def)(0)).unwrap();
        for b in kits {
            let objects = (b.def)(0).objects;
            // Two registry entries may share a definition (the demo's nodes), never a
            // layout unless they do.
            let same_def = core::ptr::eq((a.def)(0), (b.def)(0)) || a.name == b.name;
            if same_def {
                assert!(od.built_on(objects), "{} on its own objects", a.name);
            } else {
                assert!(
                    !od.built_on(objects),
                    "{} built on {}'s objects",
                    a.name,
                    b.name
                );
            }
        }
    }
}

#[test]
fn handle_arrays_step_through_subindexes_and_records() {
    use oxicat_devices::tue_es030::device::OBJECTS;
    let od = Od::<ROOM>::new(&oxicat_devices::tue_es030::device::DEF).unwrap();
    let sp: [Var<i16>; 3] = Var::across(OBJECTS, 0x7000, 2);
    let frf: [Var<i16>; 22] = Var::subs(OBJECTS, 0x6021, 1);
    for (k, v) in sp.iter().enumerate() {
        assert_eq!(
            v.entry(),
            od.var::<i16>(0x7000 + k as u16, 2).unwrap().entry()
        );
    }
    for (k, v) in frf.iter().enumerate() {
        assert_eq!(
            v.entry(),
            od.var::<i16>(0x6021, k as u8 + 1).unwrap().entry()
        );
    }
}
